"""One-off studies: each script measured a question once; its table is on the docs page that cites it."""
