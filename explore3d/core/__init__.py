"""Floor 0, the core: constants, tolerances, input checks, interrupt and output-file handling and
the settings dataclasses every floor above shares.  Imports nothing else of the package."""
