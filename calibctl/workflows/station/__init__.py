"""``calibctl station``: one warm process calibrating unit after unit at a factory station.

May import every workflow room below it (camera's capture and solve, and what they import); nothing
imports it but the CLI. The offline spool (issue 24, item 4) is not here yet.
"""
