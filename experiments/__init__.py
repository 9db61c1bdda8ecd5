"""Command-line experiments of jaxterrain: ``python -m experiments <command> [options]``."""
