"""Readers of flight logs, bags and video into one columnar time-series model (`pipeline.ingest.model`)."""
