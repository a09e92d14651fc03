"""``calibctl diff``: two stored calibrations compared (core.compare does the numbers): camera versions
by their projection difference and its significance, with an SVG map. Reads the store through
``store_admin.records``; may import report (the SVG writers), board, store_admin and exports.
"""
