"""Many runs at once: job.py says what one run is (Job, JobResult, Backend, run_job),
parallel.py runs jobs in worker processes (or, for --backend ray, hands them to
ray_backend.py, which runs each as a Ray task), sweep.py runs a scenario over a grid
of overrides and seeds, bench.py runs the catalogue of the lecture's phenomena
(bench_catalogue.py) and writes the report, with the analyses beyond the summary
metrics in analysis.py."""
