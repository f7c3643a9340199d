"""From a scenario file to the objects of a run: scenario.py loads and validates
scenarios/*.toml into frozen dataclasses; build.py turns one into the plant, law,
reference, initial estimates, noise and events (the first arrow of the data flow)."""
