"""Floor 8, the application: the pipeline (run, reconstruct, report), the CLI and its one schema of
run settings, sweeps and their report, compare, Table I, pictures and exports."""
