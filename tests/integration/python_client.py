#!/usr/bin/env python3
"""A third-party headcast sender in Python: Debian's python3-grpcio and the
project's proto/headcast.proto only (code generated here with protoc).

    python_client.py --proto-dir proto --target 127.0.0.1:50051 --token T \
        --avatar-id demo --recording talk.hcrec [--fps 30]

Reads a parameter recording, opens a session, and streams every frame as a
ParamCodec key frame (the simplest valid packet; see common/codec/param_codec.h
and range_coder.h):
  byte 0: version (2) << 6 | key flag 0x20 (chain bits 0)
  varint sequence, varint capture time in ms
  range-coded: the confidence level (0..15), then round(value / step) of every
        value, each an integer under adaptive binary models (a fresh set for
        the confidence, one shared set for the values).
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


class RangeEncoder:
    """The binary range coder of common/codec/range_coder.cc, bit for bit."""

    def __init__(self):
        self.out = bytearray()
        self.low = 0
        self.range = 0xFFFFFFFF

    def _carry(self):
        for i in range(len(self.out) - 1, -1, -1):
            if self.out[i] != 0xFF:
                self.out[i] += 1
                return
            self.out[i] = 0

    def _normalise(self):
        if self.low > 0xFFFFFFFF:
            self._carry()
            self.low &= 0xFFFFFFFF
        while self.range < (1 << 24):
            self.out.append(self.low >> 24)
            self.low = (self.low << 8) & 0xFFFFFFFF
            self.range = (self.range << 8) & 0xFFFFFFFF

    def _split(self, bit, bound):
        if bit:
            self.low += bound
            self.range -= bound
        else:
            self.range = bound
        self._normalise()

    def encode(self, bit, model):  # model: [p0], the probability of 0 in 1/4096
        bound = (self.range >> 12) * model[0]
        model[0] = model[0] - (model[0] >> 4) if bit else model[0] + ((4096 - model[0]) >> 4)
        self._split(bit, bound)

    def bypass(self, bit):
        self._split(bit, self.range >> 1)

    def finish(self):
        end = self.low + self.range
        for zero_bits in (32, 24, 16, 8, 0):
            mask = (1 << zero_bits) - 1
            value = (self.low + mask) & ~mask
            if value < end:
                break
        if value > 0xFFFFFFFF:
            self._carry()
            value &= 0xFFFFFFFF
        self.out += value.to_bytes(4, "big")
        return bytes(self.out).rstrip(b"\0")


class IntModel:
    MAX_BITS, LENGTH_MODELS = 42, 12

    def __init__(self):
        self.zero = [[2048] for _ in range(3)]
        self.sign = [[2048] for _ in range(3)]
        self.length = [[2048] for _ in range(self.LENGTH_MODELS)]
        self.second = [[2048] for _ in range(self.LENGTH_MODELS)]
        self.previous = 0

    def encode(self, v, rc):
        context = 0 if self.previous < 0 else 1 if self.previous == 0 else 2
        self.previous = v
        rc.encode(v != 0, self.zero[context])
        if v == 0:
            return
        rc.encode(v < 0, self.sign[context])
        m = min(abs(v), (1 << self.MAX_BITS) - 1)
        n = m.bit_length()
        last = self.LENGTH_MODELS - 1
        for j in range(1, n):
            rc.encode(1, self.length[min(j - 1, last)])
        if n < self.MAX_BITS:
            rc.encode(0, self.length[min(n - 1, last)])
        if n >= 2:
            rc.encode((m >> (n - 2)) & 1, self.second[min(n - 2, last)])
        for b in range(n - 3, -1, -1):
            rc.bypass((m >> b) & 1)


def key_frame(frame, layout_steps, components, t0):
    values = [frame.expression[c] if c < len(frame.expression) else 0.0 for c in components]
    for field in ("jaw", "neck", "left_eye", "right_eye", "cam_rotation", "cam_translation"):
        vec = list(getattr(frame, field)) or [0.0, 0.0, 0.0]
        values.extend(vec)
    packet = bytes([(2 << 6) | 0x20]) + varint(frame.sequence)
    packet += varint(max(0, int(round((frame.capture_time_s - t0) * 1000))))
    rc = RangeEncoder()
    IntModel().encode(int(round(min(max(frame.confidence, 0.0), 1.0) * 15)), rc)
    values_model = IntModel()
    for value, step in zip(values, layout_steps):
        values_model.encode(int(round(value / step)), rc)
    return packet + rc.finish()


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
                                  steps=steps, key_frame_interval=1, fps=args.fps, codec_version=2,
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
