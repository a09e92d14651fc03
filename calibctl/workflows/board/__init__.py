"""Registered boards: ``board add/list/show`` with the measured square size and its provenance, the desk
gauge, and ``board_spec`` (a stored board revision as the core geometry every solve uses). May import
``store_admin`` and ``exports``.
"""
