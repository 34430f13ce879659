#!/usr/bin/env python3
"""Summarises a netlab run: on-wire bitrate per direction, packets, capture-to-
arrival latency (and whether it grows), frames; writes netlab.json and netlab.png."""
import argparse
import csv
import json
import os
import statistics


def percentile(values, p):
    if not values:
        return None
    v = sorted(values)
    k = (len(v) - 1) * p / 100
    lo = int(k)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dir", required=True)
    ap.add_argument("--mode", required=True)
    ap.add_argument("--rate", type=float, default=0)
    ap.add_argument("--fps", type=float, default=30)
    ap.add_argument("--duration", type=float, default=0)
    args = ap.parse_args()
    d = args.dir
    rows = [r for r in csv.DictReader(open(os.path.join(d, "timeline.csv")))]
    rows = [{k: float(v) for k, v in r.items()} for r in rows if float(r["up_bytes"]) > 0]
    latency = []
    if os.path.exists(os.path.join(d, "latency.csv")):
        for r in csv.DictReader(open(os.path.join(d, "latency.csv"))):
            latency.append((float(r["arrival_s"]), float(r["latency_ms"])))
    sender = json.load(open(os.path.join(d, "sender.json"))) if os.path.exists(os.path.join(d, "sender.json")) else {}
    receiver = json.load(open(os.path.join(d, "receiver.json"))) if os.path.exists(os.path.join(d, "receiver.json")) else {}

    summary = {"mode": args.mode, "rate_limit_kbit": args.rate or None, "fps": args.fps, "duration_s": args.duration}
    if len(rows) >= 3:
        # Steady state: from the second sample on (connection set-up excluded).
        a, b = rows[1], rows[-1]
        span = b["t"] - a["t"]
        summary["uplink_kbps_on_wire"] = 8e-3 * (b["up_bytes"] - a["up_bytes"]) / span
        summary["downlink_kbps_on_wire"] = 8e-3 * (b["down_bytes"] - a["down_bytes"]) / span
        summary["uplink_packets_per_s"] = (b["up_packets"] - a["up_packets"]) / span
        summary["downlink_packets_per_s"] = (b["down_packets"] - a["down_packets"]) / span
        summary["measured_over_s"] = span
    if sender:
        summary["payload_kbps"] = sender.get("payload_kbps")
        summary["frames_sent"] = sender.get("frames_sent")
        summary["frames_dropped_at_sender"] = sender.get("frames_dropped")
        summary["messages"] = sender.get("messages")
        summary["frames_per_message"] = (sender["frames_sent"] / sender["messages"]) if sender.get("messages") else None
        summary["reconnects"] = max(0, sender.get("connects", 1) - 1)
        summary["frames_as"] = "datagrams" if sender.get("datagrams", 0) > 0 else "stream"
        summary["datagrams"] = sender.get("datagrams", 0)
        summary["datagrams_lost"] = sender.get("receiver_datagrams_lost", 0)
        summary["key_frame_requests"] = sender.get("key_frame_requests", 0)
    if receiver:
        summary["frames_received"] = receiver.get("frames_received")
        summary["frames_bad"] = receiver.get("frames_bad")
    if latency:
        lat = [l for _, l in latency]
        summary["latency_ms_p50"] = percentile(lat, 50)
        summary["latency_ms_p95"] = percentile(lat, 95)
        summary["latency_ms_max"] = max(lat)
        n = max(1, len(lat) // 5)
        summary["latency_ms_median_first_fifth"] = statistics.median(lat[:n])
        summary["latency_ms_median_last_fifth"] = statistics.median(lat[-n:])
        summary["latency_growth_ms"] = summary["latency_ms_median_last_fifth"] - summary["latency_ms_median_first_fifth"]
        # Once streaming: the frames after the first arrival over the time to the last
        # (the call's start-up, handshakes on a narrow link, excluded).
        t_first, t_last = latency[0][0], latency[-1][0]
        after_first = sum(1 for t, _ in latency if t > t_first)
        summary["fps_delivered_streaming"] = after_first / (t_last - t_first) if t_last > t_first else None
    summary["what_latency_means"] = ("capture on the sender to arrival (decoded) at the receiver, same host clock; "
                                     "includes batching, queueing in the rate limiter and the network")
    json.dump(summary, open(os.path.join(d, "netlab.json"), "w"), indent=2)
    print(json.dumps(summary, indent=2))

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("netlab: matplotlib missing, no plot")
        return
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=False)
    t = [r["t"] for r in rows]
    up = [8e-3 * (rows[i]["up_bytes"] - rows[i - 1]["up_bytes"]) / max(1e-3, rows[i]["t"] - rows[i - 1]["t"]) for i in range(1, len(rows))]
    down = [8e-3 * (rows[i]["down_bytes"] - rows[i - 1]["down_bytes"]) / max(1e-3, rows[i]["t"] - rows[i - 1]["t"]) for i in range(1, len(rows))]
    ax1.plot(t[1:], up, label="sender → receiver (on the wire)")
    ax1.plot(t[1:], down, label="receiver → sender (on the wire)")
    if args.rate:
        ax1.axhline(args.rate, color="gray", linestyle="--", label=f"tbf limit {args.rate:g} kbit/s")
    ax1.set_ylabel("kbit/s")
    ax1.set_title(f"headcast netlab ({args.mode}, {args.fps:g} fps" + (f", {args.rate:g} kbit/s link)" if args.rate else ", unlimited)"))
    ax1.legend(fontsize=8)
    if latency:
        t0 = latency[0][0]
        ax2.plot([a - t0 for a, _ in latency], [l for _, l in latency], ".", markersize=2)
        ax2.set_ylabel("capture → arrival, ms")
        ax2.set_xlabel("seconds")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "netlab.png"), dpi=100)
    print("netlab: wrote", os.path.join(d, "netlab.json"), "and netlab.png")


if __name__ == "__main__":
    main()
