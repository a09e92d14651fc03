"""The store as a user meets it: opening it, history, show, export, rollback (``records``), signing keys
(``keys``) and database creation and migration (``database``). May import ``exports`` only.
"""
