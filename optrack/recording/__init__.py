"""Recordings: write and read sessions of RGB-D frames with optional ground truth."""

from optrack.recording.format import (
    RECORDING_PARAMS,
    BoardTruth,
    GroundTruth,
    IndexEntry,
    Manifest,
    PersonTruth,
    RecordingError,
    SensorInfo,
)
from optrack.recording.reader import Recording, is_recording
from optrack.recording.writer import RecordingWriter

__all__ = [
    "RECORDING_PARAMS",
    "BoardTruth",
    "GroundTruth",
    "IndexEntry",
    "Manifest",
    "PersonTruth",
    "Recording",
    "RecordingError",
    "RecordingWriter",
    "SensorInfo",
    "is_recording",
]
