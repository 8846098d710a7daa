"""A flight folder's files, read once by the readers `ridgeloc inspect` uses, and what each supplies.

The logs, bags, MCAP, SRT, full-motion videos and plain videos in the folder (a ROS 2 bag folder counts as one
file); drone photos and GeoTIFF DEMs beside them; companions (frames CSV, truth files, configs) are left out, as
`inspect` leaves them. `flight_files` chooses the telemetry and the video of one flight from them, or says in one
line why it cannot.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import InputError, RidgelocError
from pipeline.ingest.dispatch import read_file
from pipeline.ingest.inspect import expand_flight_folders
from pipeline.ingest.merge import merge_logs
from pipeline.ingest.model import FlightLog
from pipeline.ingest.photo import PHOTO_SUFFIXES

# what a file can supply, in the order `ridgeloc inspect` reads them
ROLES = ("position", "attitude", "gimbal", "range", "frames", "camera_info", "field_of_view")
# what localization cannot do without (a laser range is optional: vision alone locates)
NEEDED = ("position", "attitude", "gimbal", "frames")
DEM_SUFFIXES = (".tif", ".tiff")


@dataclass
class FolderFile:
    """One readable input: its path, and the FlightLog its reader made of it."""

    path: Path
    log: FlightLog

    @property
    def supplies(self) -> list[str]:
        return [r for r in ROLES if getattr(self.log, r) is not None]

    @property
    def plain_video(self) -> bool:
        """A video with no telemetry of its own (not a full-motion video with KLV)."""
        return self.supplies == ["frames"]

    def describe(self) -> str:
        return f"{self.path.name} ({', '.join(self.supplies) or 'nothing localization uses'})"


@dataclass
class Folder:
    """What `read_folder` found: readable files, unreadable ones with their one-line errors, photos, DEMs."""

    root: Path
    files: list[FolderFile] = field(default_factory=list)
    unreadable: list[str] = field(default_factory=list)
    photos: list[Path] = field(default_factory=list)
    dems: list[Path] = field(default_factory=list)

    def describe(self) -> str:
        parts = [f.describe() for f in self.files]
        if self.photos:
            parts.append(f"{len(self.photos)} photo(s)")
        if self.dems:
            parts.append(", ".join(p.name for p in self.dems) + " (DEM)")
        parts += [f"{u} (unreadable)" for u in self.unreadable]
        return "found " + ("; ".join(parts) if parts else "no logs, videos or photos")


def read_folder(root) -> Folder:
    """Read every flight file of `root` (a folder, or one file: a full-motion video, a log) with the default
    mappings; a folder's unreadable files are listed (`unreadable`: "name: why"). InputError when `root` does not
    exist or is one file that cannot be read."""
    root = Path(root)
    if not root.exists():
        raise InputError("no such file or folder", root)
    folder = Folder(root)
    if root.is_dir() and not (root / "metadata.yaml").is_file():  # a flight folder, not a ROS 2 bag's
        children = sorted(c for c in root.iterdir() if not c.name.startswith("."))
        folder.photos = [c for c in children if c.is_file() and c.suffix.lower() in PHOTO_SUFFIXES]
        folder.dems = [c for c in children if c.is_file() and c.suffix.lower() in DEM_SUFFIXES]
        paths = [p for _, p in expand_flight_folders([root]) if p != root]
    else:  # one file: its reader's own one-line error when it cannot be read
        folder.files.append(FolderFile(root, read_file(root)))
        return folder
    for p in paths:
        try:
            folder.files.append(FolderFile(p, read_file(p)))
        except RidgelocError as exc:
            why = str(exc)
            if exc.path and why.startswith(f"{exc.path}: "):  # named once, by its name in the folder
                why = why[len(exc.path) + 2:]
            folder.unreadable.append(f"{p.name}: {why}")
    return folder


@dataclass(frozen=True)
class FlightFiles:
    """The files of one video flight: telemetry (logs, bags, SRT, full-motion video) and the video, None when the
    frames come from a bag or a full-motion video; `log` all of them read and merged."""

    telemetry: tuple[Path, ...]
    video: Path | None
    log: FlightLog


def flight_files(folder: Folder) -> FlightFiles:
    """The telemetry and the video of the folder's flight; InputError (one line: what was found, what is
    missing) when the files do not make one: no video or images, two videos, no position, attitude or gimbal."""
    videos = [f for f in folder.files if f.plain_video]
    telemetry = [f for f in folder.files if not f.plain_video]
    clips = [f for f in telemetry if "fmv" in f.log.formats]  # each its own flight: frames and telemetry in one
    if len(clips) > 1:
        raise InputError(f"{folder.describe()}; {len(clips)} full-motion videos, each a flight of its own: put each "
                         f"in a folder of its own, or init one clip (`ridgeloc init {clips[0].path} -o "
                         f"{clips[0].path.stem}.yaml`)", folder.root)
    if len(videos) > 1:
        srt_stems = {f.path.stem.lower() for f in telemetry if f.path.suffix.lower() == ".srt"}
        paired = [v for v in videos if v.path.stem.lower() in srt_stems]  # a DJI video beside its SRT
        if len(paired) != 1:
            raise InputError(f"{folder.describe()}; {len(videos)} videos: put each flight in a folder of its own",
                             folder.root)
        videos = paired
    log = merge_logs([f.log for f in telemetry]) if telemetry else FlightLog(path=str(folder.root))
    if videos:  # the video's frames, not a bag's images (files.video wins over them in a run too)
        log = dataclasses.replace(log, frames=videos[0].log.frames)
    missing = [q for q in NEEDED if getattr(log, q) is None]
    relative_srt = "srt" in log.formats  # an SRT's heights above take-off: its take-off altitude is filled in
    if log.position is not None and (log.position.alt_datum == "missing" or
                                     (log.position.alt_datum == "relative" and not relative_srt)):
        missing.append("altitudes above the ellipsoid or sea level (the positions' are "
                       f"{'missing' if log.position.alt_datum == 'missing' else 'relative to the take-off point'})")
    if missing or not telemetry:
        what = ", ".join(missing) if missing else "telemetry"
        if "gimbal" in missing and log.attitude is not None:
            what += (" (for a camera fixed to the airframe, with no gimbal, write the config by hand with "
                     "camera: {fixed_to_body: true}: docs/flight_config.md)")
        raise InputError(f"{folder.describe()}; missing for localization: {what}", folder.root)
    return FlightFiles(tuple(f.path for f in telemetry), videos[0].path if videos else None, log)
