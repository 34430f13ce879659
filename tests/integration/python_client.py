#!/usr/bin/env python3
"""A third-party headcast sender in Python: Debian's python3-grpcio and the
project's proto/headcast.proto only (code generated here with protoc).

    python_client.py --proto-dir proto --target 127.0.0.1:50051 --token T \
        --avatar-id demo --recording talk.hcrec [--fps 30]

Reads a parameter recording, opens a session, and streams every frame as a
ParamCodec key frame (the simplest valid packet; see common/codec/param_codec.h):
  byte 0: version (1) << 6 | key flag 0x20
  varint 0 (key frame), varint sequence, varint capture time in ms
  bits: 4-bit confidence, then every value as signed Exp-Golomb of order 6
        of round(value / step), most significant bit first.
Prints a JSON summary; exits non-zero if the receiver refused the session.
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
import hcrec  # noqa: E402  (tests/testing/hcrec.py: the generated proto module, .hcrec reading)


def varint(v):
    out = bytearray()
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)
    return bytes(out)


class Bits:
    def __init__(self):
        self.bits = []

    def put(self, value, count):
        self.bits.extend((value >> i) & 1 for i in range(count - 1, -1, -1))

    def exp_golomb(self, v, k):
        x = v + (1 << k)
        n = x.bit_length() - 1
        self.bits.extend([0] * (n - k))
        self.put(x, n + 1)

    def signed(self, v, k):
        self.exp_golomb(2 * v if v >= 0 else -2 * v - 1, k)

    def bytes(self):
        padded = self.bits + [0] * (-len(self.bits) % 8)
        return bytes(int("".join(map(str, padded[i:i + 8])), 2) for i in range(0, len(padded), 8))


def key_frame(frame, layout_steps, components, t0):
    values = [frame.expression[c] if c < len(frame.expression) else 0.0 for c in components]
    for field in ("jaw", "neck", "left_eye", "right_eye", "cam_rotation", "cam_translation"):
        vec = list(getattr(frame, field)) or [0.0, 0.0, 0.0]
        values.extend(vec)
    packet = bytes([(1 << 6) | 0x20]) + varint(0) + varint(frame.sequence)
    packet += varint(max(0, int(round((frame.capture_time_s - t0) * 1000))))
    bits = Bits()
    bits.put(int(round(min(max(frame.confidence, 0.0), 1.0) * 15)), 4)
    for value, step in zip(values, layout_steps):
        bits.signed(int(round(value / step)), 6)
    return packet + bits.bytes()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--proto-dir", required=True)
    ap.add_argument("--target", required=True)
    ap.add_argument("--token", required=True)
    ap.add_argument("--avatar-id", required=True)
    ap.add_argument("--recording", required=True)
    ap.add_argument("--fps", type=float, default=30)
    args = ap.parse_args()

    pb = hcrec.load_proto(args.proto_dir)
    import grpc  # noqa: E402  (python3-grpcio)

    header, frames = hcrec.read_recording(args.recording, pb)

    components = list(range(header.num_expression))
    steps = [0.01] * len(components) + [0.001] * 15 + [0.0002] * 3
    hello = pb.Uplink(hello=pb.Hello(
        protocol_version=1, avatar_id=args.avatar_id, sender_name="python third-party client",
        layout=pb.ParameterLayout(num_expression=header.num_expression, expression_components=components,
                                  steps=steps, key_frame_interval=1, fps=args.fps, codec_version=1,
                                  head_model_fingerprint=header.head_model_fingerprint)))

    def uplink():
        yield hello
        t0 = frames[0].capture_time_s
        start = time.monotonic()
        for f in frames:
            delay = (f.capture_time_s - t0) - (time.monotonic() - start)
            if delay > 0:
                time.sleep(delay)
            packet = key_frame(f, steps, components, t0)
            yield pb.Uplink(frames=pb.Frames(payload=varint(len(packet)) + packet, count=1, send_time_s=time.monotonic()))
        time.sleep(0.3)  # let the last Stats arrive
        yield pb.Uplink(bye=pb.Bye(reason="python client done"))

    channel = grpc.insecure_channel(args.target)
    session = channel.stream_stream("/headcast.v1.Headcast/Session",
                                    request_serializer=pb.Uplink.SerializeToString,
                                    response_deserializer=pb.Downlink.FromString)
    summary = {"frames_sent": len(frames), "welcome": False, "reject": "", "errors": [], "stats": None}
    try:
        for down in session(uplink(), metadata=[("authorization", f"Bearer {args.token}")], timeout=60):
            kind = down.WhichOneof("message")
            if kind == "welcome":
                summary["welcome"] = True
                summary["session_id"] = down.welcome.session_id
            elif kind == "reject":
                summary["reject"] = pb.Reject.Reason.Name(down.reject.reason) + ": " + down.reject.message
            elif kind == "error":
                summary["errors"].append(down.error.message)
            elif kind == "stats":
                summary["stats"] = {"frames_received": down.stats.frames_received, "frames_bad": down.stats.frames_bad}
    except grpc.RpcError as e:
        summary["rpc_status"] = str(e.code())
    print(json.dumps(summary, indent=2))
    return 0 if summary["welcome"] and not summary["reject"] else 1


if __name__ == "__main__":
    sys.exit(main())
