"""Python access to headcast's files for test scripts: the generated proto
module (protoc at run time, python3-protobuf) and .hcrec parameter recordings
(8-byte magic, then a length-delimited RecordingHeader and FrameParams)."""
import os
import subprocess
import sys
import tempfile

# The varint reader of the project's own Python module (python/headcast_files.py).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "python"))
from headcast_files import _varint as read_varint  # noqa: E402


def load_proto(proto_dir):
    """Generates headcast_pb2 from proto_dir/headcast.proto and imports it."""
    gen = tempfile.mkdtemp(prefix="headcast_py_")
    subprocess.run(["protoc", f"--python_out={gen}", "-I", proto_dir, "headcast.proto"], check=True)
    sys.path.insert(0, gen)
    import headcast_pb2  # noqa: E402

    return headcast_pb2


def read_recording(path, pb):
    """(header, [FrameParams]) of a .hcrec file; exits with a message if it is not one."""
    data = open(path, "rb").read()
    if data[:8] != b"HCASTREC":
        sys.exit(f"{path}: not a headcast recording")
    length, pos = read_varint(data, 8)
    header = pb.RecordingHeader.FromString(data[pos:pos + length])
    pos += length
    frames = []
    while pos < len(data):
        length, pos = read_varint(data, pos)
        frames.append(pb.FrameParams.FromString(data[pos:pos + length]))
        pos += length
    return header, frames
