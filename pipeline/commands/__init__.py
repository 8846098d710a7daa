"""Command-line layer: one module per `ridgeloc` subcommand, each thin over library functions."""
