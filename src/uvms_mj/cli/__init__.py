"""The command line: thin wrappers that parse, call and report."""
