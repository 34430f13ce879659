#!/usr/bin/env python3
"""Writes bench/REPORT.md from the JSON results of bench/run_all.sh."""
import argparse, datetime, json, os, platform, subprocess, zipfile


def load(res, name):
    p = os.path.join(res, name)
    return json.load(open(p)) if os.path.exists(p) else None


def f(v, d=1):
    return "—" if v is None else (f"{v:.{d}f}" if isinstance(v, (int, float)) else str(v))


def machine():
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
    mem = next((int(l.split()[1]) for l in open("/proc/meminfo") if l.startswith("MemTotal")), 0) / 2 ** 20
    return f"{os.cpu_count()} cores ({cpu}), {mem:.0f} GiB, {platform.system()} {platform.release()}, no GPU"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", required=True)
    ap.add_argument("--command", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    r = a.results
    rel = os.path.relpath(r, os.path.dirname(a.out))
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=os.path.dirname(a.out)).stdout.strip()
    except OSError:
        commit = "?"
    L = ["# headcast benchmark report", "",
         f"Made by `{a.command}` on {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}, commit {commit}.",
         f"Machine: {machine()}. Every figure below comes from the JSON in `{rel}/` (each JSON also holds the",
         "`headcast-bench` command that reproduces it). The machine is shared: timings vary by ~10-30 % between runs;",
         "comparisons are made within one run.", ""]

    L += ["## Receiver: avatar synthesis on the CPU", "",
          "| output | fps (median) | ms p95 | threads | stages (ms, median) |", "|---|---|---|---|---|"]
    for res in (128, 256, 512):
        j = load(r, f"render_{res}.json")
        if j:
            st = ", ".join(f"{k} {v:.1f}" for k, v in j.get("stage_ms_median", {}).items())
            L.append(f"| {res}² | {f(j.get('fps_median'))} | {f(j.get('ms_p95'))} | {j.get('threads', '?')} | {st} |")
    h = load(r, "render_256_vs_headnerf.json")
    if h and "headnerf_sized" in h:
        L += ["", f"Side by side at 256², same run: ours {f(h['ms_median'])} ms/frame against the HeadNeRF-sized "
                  f"configuration (32×32×256 feature map, 64 uniform samples, MLP 8×384) {f(h['headnerf_sized']['ms_median'])}"
                  f" ms/frame: **{f(h['speedup_vs_headnerf_sized'])}× faster**."]
    L.append("")

    t = load(r, "track.json")
    L += ["## Sender: tracking per frame (one core, `taskset -c 0`)", ""]
    if t and "ms_per_frame_median" in t:
        L += [f"{t.get('video')} with {t.get('head_model')}: {t.get('fitted_frames')}/{t.get('frames')} frames fitted, "
              f"**{f(t['ms_per_frame_median'])} ms median**, {f(t.get('ms_per_frame_p95'))} ms p95 (landmarks "
              f"{f(t.get('track_ms_median'))}, fit {f(t.get('fit_ms_median'))}); landmark error "
              f"{f(t.get('landmark_error_iod_mean'), 4)} of the eye distance.", ""]
    else:
        L += [f"Not run: {t.get('skipped') if t else 'no result'}.", ""]

    c = load(r, "codec.json")
    if c:
        L += ["## Parameter codec", "",
              f"{f(c.get('bits_per_frame_mean'))} bits per frame on average (key frames {f(c.get('bits_per_frame_key_mean'))}, "
              f"others {f(c.get('bits_per_frame_delta_mean'))}): {f(c.get('payload_kbps_at_30fps'), 2)} kbit/s of payload at 30 fps "
              f"({c.get('values_per_frame')} values per frame).", ""]

    L += ["## On the wire", "", "| link | uplink on the wire (kbit/s) | payload (kbit/s) | frames/message | "
          "capture→arrival p50 / p95 (ms) | dropped |", "|---|---|---|---|---|---|"]
    for name, label in (("netlab_loopback", "loopback, unconstrained, 30 fps"), ("netlab_8kbit", "tbf 8 kbit/s"),
                        ("netlab_16kbit", "tbf 16 kbit/s"), ("netlab_32kbit", "tbf 32 kbit/s")):
        n = load(os.path.join(r, name), "netlab.json")
        if n:
            L.append(f"| {label} | {f(n.get('uplink_kbps_on_wire'), 2)} | {f(n.get('payload_kbps'), 2)} | "
                     f"{f(n.get('frames_per_message'))} | {f(n.get('latency_ms_p50'), 0)} / {f(n.get('latency_ms_p95'), 0)} | "
                     f"{n.get('frames_dropped_at_sender')} |")
        else:
            L.append(f"| {label} | not run (tbf links need root) | | | | |")
    L.append("")

    # Real people's tracks beside the synthetic sequence: bench/codec_real.sh and
    # bench/narrow_links.sh write their tables into results/narrow_links.md.
    if os.path.exists(os.path.join(r, "narrow_links.md")):
        L += [f"Real people's tracks and the narrow links: [{rel}/narrow_links.md]({rel}/narrow_links.md) "
              "(the codec on ICT-FaceKit tracks of the shared clips, netlab at 4, 8 and 16 kbit/s, synthetic and real "
              "side by side, frames on the gRPC stream and as datagrams).", ""]

    d = load(os.path.join(r, "demo"), "report.json")
    if d:
        g, st = d["glass_to_glass_ms"], d["stages_ms_median"]
        L += ["## Glass to glass (sender and receiver on this machine, `deploy/demo.sh`)", "",
              f"{d['frames']['shown']} frames shown at {f(d.get('fps_shown'))} fps: **p50 {f(g['p50'])} ms, p95 {f(g['p95'])} ms** "
              f"from capture to display. Stages (median ms): " + ", ".join(f"{k} {f(v)}" for k, v in st.items()) +
              f". Uplink {f(d['uplink_kbps'].get('payload'), 2)} kbit/s payload, {f(d['uplink_kbps'].get('on_wire'), 2)} kbit/s on the wire.",
              "", f"![latency]({rel}/demo/latency.png)", ""]

    L += ["## Training", "", "| resolution | pretrain samples/s | fine-tune samples/s | SSIM term ms (separable / 2D window) | fine-tune data |",
          "|---|---|---|---|---|"]
    for res in (128, 256):
        j = load(r, f"train_{res}.json")
        if j:
            L.append(f"| {res}² | {f(j.get('pretrain_samples_per_s'), 2)} | {f(j.get('finetune_samples_per_s'), 2)} | "
                     f"{f(j.get('ssim_ms_median'), 1)} / {f(j.get('ssim_full_window_ms_median'), 1)} | {j.get('finetune_data')} |")
    L.append("")

    real = os.path.join(r, "real_person.md")  # bench/real_person.sh: too long for this run, kept apart
    if os.path.exists(real):
        L += ["## A real person's avatar (`bench/real_person.sh`)", "", open(real).read().strip(), ""]

    x = load(r, "x264.json")
    L += ["## headcast against x264 on the same footage", ""]
    if x and "x264" in x:
        L += [f"{x['frames']} test frames at {x['size'][0]}×{x['size'][1]}, 30 fps; {x['x264_settings']}. {x['scoring']}.", "",
              "| codec | kbit/s | PSNR (dB) | SSIM |", "|---|---|---|---|"]
        for p in x["x264"]:
            L.append(f"| x264 (target {p['target_kbps']:g}) | {f(p['kbps'])} | {f(p['psnr_db'], 2)} | {f(p['ssim'], 3)} |")
        for h in x["headcast"]:
            L.append(f"| **headcast** ({h['setting']}) | {f(h['kbps_on_wire'])} on the wire | {f(h['psnr_db'], 2)} | {f(h['ssim'], 3)} |")
        L += ["", f"![rate-quality]({rel}/x264.png)", ""]
    else:
        L += [f"Not run: {x.get('skipped') if x else 'no result'}.", ""]

    g = load(r, "rgbd.json")
    if g:
        L += ["## RGB-D fit per frame (METHOD §3)", "", f"`{g.get('command', '')}`: {g.get('what', '')}.", "",
              "| depth noise, cloud | points | ms median | ms p95 | first frame ms | accuracy (mm) | face RMS (mm) | head position (mm) |",
              "|---|---|---|---|---|---|---|---|"]
        for k, v in g.items():
            if isinstance(v, dict) and "ms_per_frame_median" in v:
                L.append(f"| {k} | {f(v.get('cloud_points_median'), 0)} | {f(v['ms_per_frame_median'], 1)} | "
                         f"{f(v.get('ms_per_frame_p95'), 1)} | {f(v.get('first_frame_ms'), 0)} | "
                         f"{f(v.get('accuracy_mm_median'), 3)} | {f(v.get('face_rms_mm_median'), 3)} | "
                         f"{f(v.get('head_position_error_mm_median'), 3)} |")
        L.append("")

    L += ["## Other suites", ""]
    for name in ("headmodel", "raster", "meshfit"):
        j = load(r, f"{name}.json")
        if not j:
            continue
        scal = {}
        def walk(prefix, v):  # numbers anywhere in the result, named by their path
            if isinstance(v, dict):
                for k, x in v.items():
                    walk(f"{prefix}.{k}" if prefix else k, x)
            elif isinstance(v, list):
                for i, x in enumerate(v):
                    walk(f"{prefix}[{i}]", x)
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                scal[prefix] = v
        walk("", {k: v for k, v in j.items() if k != "machine"})
        keys = [k for k in scal if any(t in k for t in ("mm", "ms_median", "_ms", "us_median"))] or list(scal)
        L.append(f"- **{name}** (`{j.get('command', '')}`): " + ", ".join(f"{k} {f(scal[k], 3)}" for k in keys[:24]))
    L.append("")
    open(a.out, "w").write("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
