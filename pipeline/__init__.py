"""ridgeloc: UAV ground-target localization from video, telemetry and laser ranges.

Stages, in order (each a subpackage): ingest -> track -> geometry -> sync -> solve -> report.
"""

__version__ = "0.1.0"
