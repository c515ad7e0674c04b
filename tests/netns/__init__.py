"""Scripts the test suite runs inside a private network namespace (see tests/netns_util.py)."""
