"""Example flight software."""
