"""Reads headcast's files in Python with numpy only (no protobuf package):
parameter recordings (.hcrec) and avatar manifests (.hcavatar).

    import headcast_files as hf
    rec = hf.read_recording("talk.hcrec")
    rec.header["fps"], rec.expression.shape      # (N, E) float32
    rec.jaw, rec.neck, rec.left_eye, rec.right_eye, rec.cam_rotation, rec.cam_translation  # (N, 3)
    rec.capture_time_s, rec.sequence, rec.confidence                                      # (N,)
    hf.read_avatar_manifest("me.hcavatar")       # the manifest as a dict

A .hcrec file is b"HCASTREC", a varint-length-prefixed RecordingHeader, then
varint-length-prefixed FrameParams messages (proto/headcast.proto). A record
cut short at the end (a recorder killed mid-write) ends the frames there and
is reported in rec.cut, as headcast's own reader does.
"""
import json
import struct
import zipfile
from dataclasses import dataclass, field

import numpy as np

MAGIC = b"HCASTREC"
FORMAT_VERSION = 1
GROUPS = ("jaw", "neck", "left_eye", "right_eye", "cam_rotation", "cam_translation")


class FormatError(ValueError):
    """A file that is not what it claims, with the reason."""


def _varint(data, pos):
    value = shift = 0
    while True:
        if pos >= len(data) or shift > 63:
            raise FormatError("truncated varint")
        b = data[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, pos
        shift += 7


def _fields(data):
    """(field number, wire type, value) of a protobuf message: ints, bytes, or raw 4/8-byte values."""
    pos = 0
    while pos < len(data):
        key, pos = _varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(data, pos)
        elif wire == 1:
            if pos + 8 > len(data):
                raise FormatError("truncated 64-bit field")
            value, pos = data[pos:pos + 8], pos + 8
        elif wire == 2:
            length, pos = _varint(data, pos)
            if pos + length > len(data):
                raise FormatError("truncated length-delimited field")
            value, pos = data[pos:pos + length], pos + length
        elif wire == 5:
            if pos + 4 > len(data):
                raise FormatError("truncated 32-bit field")
            value, pos = data[pos:pos + 4], pos + 4
        else:
            raise FormatError(f"unknown wire type {wire}")
        yield number, wire, value


def _floats(wire, value):
    # repeated float: packed (wire 2) or one at a time (wire 5)
    return list(struct.unpack(f"<{len(value) // 4}f", value)) if wire == 2 else [struct.unpack("<f", value)[0]]


def _double(value):
    return struct.unpack("<d", value)[0]


def _frame(data):
    f = {g: [] for g in GROUPS}
    f.update(expression=[], capture_time_s=0.0, sequence=0, confidence=0.0)
    names = {1: "expression", 2: "jaw", 3: "neck", 4: "left_eye", 5: "right_eye", 6: "cam_rotation",
             7: "cam_translation"}
    for number, wire, value in _fields(data):
        if number in names:
            f[names[number]] += _floats(wire, value)
        elif number == 8:
            f["capture_time_s"] = _double(value)
        elif number == 9:
            f["sequence"] = value
        elif number == 10:
            f["confidence"] = struct.unpack("<f", value)[0]
    return f


def _subject(data):
    s = {"shape": [], "texture": [], "light": [], "intrinsics": {}}
    for number, wire, value in _fields(data):
        if number in (1, 2, 3):
            s[("shape", "texture", "light")[number - 1]] += _floats(wire, value)
        elif number == 4:
            names = {1: "fx", 2: "fy", 3: "cx", 4: "cy", 5: "width", 6: "height"}
            for n, w, v in _fields(value):
                if n in names:
                    s["intrinsics"][names[n]] = _double(v) if w == 1 else v
    return s


def _header(data):
    h = {"format_version": 0, "head_model_name": "", "head_model_fingerprint": "", "num_expression": 0,
         "fps": 0.0, "subject": _subject(b""), "source": "", "created_unix_s": 0}
    for number, wire, value in _fields(data):
        if number == 1:
            h["format_version"] = value
        elif number in (2, 3, 7):
            h[{2: "head_model_name", 3: "head_model_fingerprint", 7: "source"}[number]] = value.decode("utf-8")
        elif number == 4:
            h["num_expression"] = value
        elif number == 5:
            h["fps"] = _double(value)
        elif number == 6:
            h["subject"] = _subject(value)
        elif number == 8:
            h["created_unix_s"] = value
    return h


@dataclass
class Recording:
    header: dict
    expression: np.ndarray
    capture_time_s: np.ndarray
    sequence: np.ndarray
    confidence: np.ndarray
    groups: dict = field(default_factory=dict)
    cut: str = ""

    def __getattr__(self, name):
        if name in GROUPS:
            return self.groups[name]
        raise AttributeError(name)

    def __len__(self):
        return len(self.sequence)


def read_recording(path):
    """The whole recording; raises FormatError for a foreign file, another version or no whole frame."""
    data = open(path, "rb").read()
    if data[:8] != MAGIC:
        raise FormatError(f"{path}: not a headcast parameter recording")
    try:
        length, pos = _varint(data, 8)
        if pos + length > len(data):
            raise FormatError("truncated header")
        header = _header(data[pos:pos + length])
    except FormatError as e:
        raise FormatError(f"{path}: corrupt header ({e})") from None
    if header["format_version"] != FORMAT_VERSION:
        raise FormatError(f"{path}: recording format {header['format_version']}, this reader knows {FORMAT_VERSION}")
    pos += length
    e = header["num_expression"]
    frames, cut = [], ""
    while pos < len(data):
        try:
            length, start = _varint(data, pos)
            if start + length > len(data):
                raise FormatError("the last record is cut short")
            f = _frame(data[start:start + length])
            if len(f["expression"]) > e or any(len(f[g]) not in (0, 3) for g in GROUPS):
                raise FormatError("a record of the wrong size")
            if not np.isfinite(f["capture_time_s"]):
                raise FormatError("a capture time that is not a time")
        except FormatError as err:
            cut = f"frame {len(frames)}: {err}"
            break
        frames.append(f)
        pos = start + length
    if not frames:
        raise FormatError(f"{path}: no whole frame" + (f" ({cut})" if cut else ""))
    expression = np.zeros((len(frames), e), np.float32)
    for i, f in enumerate(frames):
        expression[i, :len(f["expression"])] = f["expression"]
    groups = {g: np.array([f[g] or [0.0, 0.0, 0.0] for f in frames], np.float32) for g in GROUPS}
    return Recording(header=header, expression=expression,
                     capture_time_s=np.array([f["capture_time_s"] for f in frames], np.float64),
                     sequence=np.array([f["sequence"] for f in frames], np.int64),
                     confidence=np.array([f["confidence"] for f in frames], np.float32), groups=groups, cut=cut)


def read_avatar_manifest(path):
    """The manifest of an .hcavatar (a zip archive) as a dict, without the weights."""
    try:
        with zipfile.ZipFile(path) as z:
            return json.loads(z.read("manifest.json"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError) as e:
        raise FormatError(f"{path}: not a headcast avatar ({e})") from None
