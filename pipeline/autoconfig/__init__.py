"""`ridgeloc init`: a flight config written from a folder of flight files (docs/init.md).

folder.py reads the folder's files with the readers of `ridgeloc inspect` and chooses the flight's telemetry and
video; timing.py puts the video on the telemetry clock and chooses the observations; draft.py gathers what the
files state and what `ridgeloc check`'s checks show (conventions, the clock estimated from the flight), with a
placeholder for every fact nothing states; text.py writes it as a commented YAML file that the flight config
loader reads.
"""

from pipeline.autoconfig.draft import Draft, FillIn, draft_flight_config
from pipeline.autoconfig.text import config_text

__all__ = ["Draft", "FillIn", "config_text", "draft_flight_config"]
