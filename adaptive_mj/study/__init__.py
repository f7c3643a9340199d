"""Many runs at once: parallel.py runs jobs in worker processes, sweep.py runs a
scenario over a grid of overrides and seeds, bench.py runs the catalogue of the
lecture's phenomena (bench_catalogue.py) and writes the report, with the analyses
beyond the summary metrics in analysis.py."""
