"""Configuration, read and resolved at the edge: the field log parsed into plain values
(:mod:`~gnomon.config.fieldlog`, its types in :mod:`~gnomon.config.specs`, its tables read by
:mod:`~gnomon.config.tables`, its numbers checked together in :mod:`~gnomon.config.plausibility`), the
registry of light kinds (:mod:`~gnomon.config.lights`), the pencil log of `gnomon calibrate lamp`
(:mod:`~gnomon.config.pencil_log`), and the whole resolved once into a scan's set-up: camera, pose,
reference planes and light model (:mod:`~gnomon.config.setup`).
"""

from gnomon.config.fieldlog import load_field_log
from gnomon.config.lights import LIGHTS, LightKind
from gnomon.config.pencil_log import PencilLog, load_pencil_log
from gnomon.config.setup import ScanSetup, frame_source, resolve_scan
from gnomon.config.specs import FieldLog

__all__ = [
    "FieldLog", "LIGHTS", "LightKind", "PencilLog", "ScanSetup", "frame_source", "load_field_log",
    "load_pencil_log", "resolve_scan",
]
