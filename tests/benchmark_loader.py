"""Import a script of benchmarks/ as a module (the scripts put benchmarks/ on sys.path; that is undone here)."""

from scripts import load_script


def load_benchmark(name: str):
    """The module of ``benchmarks/<name>.py``."""
    return load_script(f"benchmarks/{name}.py", f"{name}_benchmark")
