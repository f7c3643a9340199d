"""The sections of the `adaptive-mj bench` report, one module each: its runs (scenario + overrides) and
the analysis that turns their results into the section's text, table rows and figures. Each module
registers itself with common.register (number, key, title, the lecture's claim);
adaptive_mj/study/bench_catalogue.py imports them and assembles the catalogue in the report's order.
Section 14 (breaking points) is not here: adaptive_mj/study/bench.py runs it as the stress study.
"""
