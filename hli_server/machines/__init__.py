"""Packaged machine files: ``demo.toml`` (the built-in demo machine) and its ISG text parameter lists.

Loaded through :func:`hli_server.configuration.load_machine` (``load_machine(None)``), E-07.
"""
