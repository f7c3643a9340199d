"""The MCAP log of a run: record.py writes it while the run goes (format versioned,
see docs/LOG_FORMAT.md), replay.py reads any version back into a Trajectory (and
recovers a truncated file); adaptive_mj.runs.verify re-simulates a log and compares bit for bit."""
