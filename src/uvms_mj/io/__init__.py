"""Logs: the MCAP recorder and reader, exports."""
