"""Scenario files: schema, loading, building a run."""
