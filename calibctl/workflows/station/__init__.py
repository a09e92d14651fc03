"""``calibctl station``: one warm process calibrating unit after unit at a factory station.

May import every workflow room below it (camera's capture and solve, and what they import); nothing
imports it but the CLI. ``station`` is the loop; ``offline`` calibrates a unit into the spool while the
store is away and ``sync`` stores the spool's units in order when it is back (``store.spool``: the file).
"""
