"""Use cases: each function is one command's job, from parsed options to a stored or written result.

One room per capability, each importing only the rooms below it (docs/architecture.md): ``rig`` <-
``handeye`` <- ``camera`` <- ``report``, ``lint``, ``synth`` <- ``board`` <- ``store_admin`` <- ``exports``,
``diagnostics``. Workflows may import core, store and artifacts; never the CLI.
"""
