"""The ``rigctl`` command line: one module per verb, wired together in :mod:`rigctl.cli.main`."""
