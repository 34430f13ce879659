"""Python access to headcast's files for test scripts: the generated proto
module (protoc at run time, python3-protobuf) and .hcrec parameter recordings
(8-byte magic, then a length-delimited RecordingHeader and FrameParams)."""
import subprocess
import sys
import tempfile


def load_proto(proto_dir):
    """Generates headcast_pb2 from proto_dir/headcast.proto and imports it."""
    gen = tempfile.mkdtemp(prefix="headcast_py_")
    subprocess.run(["protoc", f"--python_out={gen}", "-I", proto_dir, "headcast.proto"], check=True)
    sys.path.insert(0, gen)
    import headcast_pb2  # noqa: E402

    return headcast_pb2


def read_varint(data, pos):
    shift = value = 0
    while True:
        b = data[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, pos
        shift += 7


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
