"""Test support that needs the checkout (the repository's sample data, ../shared) or exists only for tests and
benchmarks: fuzz targets, small writers of each log format. Not part of the installed package.

Importable as `support` from the tests (pytest puts tests/ on sys.path) and from scripts/ that add tests/ to it.
"""
