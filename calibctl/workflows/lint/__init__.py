"""What CI gates on, and what is let into a store: ``lint`` of exported files and stored records, and
``import`` (an artifact from another store is linted with this store's rules before it is stored).
May import store_admin and exports.
"""
