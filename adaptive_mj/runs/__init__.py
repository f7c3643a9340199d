"""One scenario end to end, above the closed loop (adaptive_mj.sim), the log (adaptive_mj.log) and the report
(adaptive_mj.report): runner.py builds a scenario's objects, runs it, judges it, logs it and summarises it;
verify.py re-runs a log's scenario and compares it with the log bit for bit."""
