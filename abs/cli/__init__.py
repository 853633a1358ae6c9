"""The ``abs`` command line."""
