#!/usr/bin/env bash
# Issue 60's hang replayed on the real window under Xvfb (1440x900, lavapipe), driven with xdotool, measured
# from outside: every input's answer (the app's own frame record, FLARELAB_FRAME_LOG), the UI thread's CPU while
# a bake runs and nothing is touched, the looks' thumbnails made beside the bake, memory (VmRSS sampled, VmHWM
# at the end), and the bake landing. Steps: a fresh launch on the default lens with a 1280x720 plate and its
# depth map and depth of field on (the automatic bake starts), ghosts set to ray grid 32, flare exposure
# dragged to the slider's end, Ctrl+Z, Cancel trace three times, ghosts back to the look, the Looks tab, then
# the window left alone until the bake lands.
# Usage: tests/hang_replay.sh [BIN]  (default target/release/flarelab). Needs Xvfb, xdotool, python3.
set -uo pipefail
cd "$(dirname "$0")/.."
bin=$(realpath "${1:-target/release/flarelab}")
work=$(mktemp -d)
export XDG_RUNTIME_DIR="$work"
display=:87
Xvfb $display -screen 0 1440x900x24 >/dev/null 2>&1 & xvfb=$!
sleep 1
export DISPLAY=$display
"$bin" synth-dof --size 1280x720 -o "$work/street.exr" --depth "$work/street_z.exr" >/dev/null
"$bin" preset new -o "$work/hang.json" >/dev/null
python3 - "$work" <<'PY'
import json, sys
w = sys.argv[1]
d = json.load(open(f"{w}/hang.json"))
d["background"] = f"{w}/street.exr"
d["dof"]["enabled"] = True
d["dof"]["depth"] = f"{w}/street_z.exr"
json.dump(d, open(f"{w}/hang.json", "w"))
PY
mkdir -p "$work/home" "$work/cache"
HOME="$work/home" FLARELAB_CACHE_DIR="$work/cache" FLARELAB_WINDOW=1440x900 FLARELAB_PRESET="$work/hang.json" \
    FLARELAB_FRAME_LOG="$work/frames.txt" "$bin" >"$work/app.log" 2>&1 &
app=$!
inputs="$work/inputs.txt"
: >"$inputs"
# Memory, sampled twice a second until the app ends.
( while kill -0 $app 2>/dev/null; do
    awk '/VmRSS/ {print $2}' /proc/$app/status 2>/dev/null >>"$work/rss.txt"; sleep 0.5; done ) &
note() { echo "$(date +%s.%N) $1" >>"$inputs"; }
act() { note "$1"; shift; xdotool "$@"; }
sleep 10
# Xvfb has no window manager: the window gets the keyboard only when given it.
xdotool search --name FlareLab windowfocus 2>/dev/null
act "ghosts-combo" mousemove 52 856 click 1; sleep 0.7
act "ray-grid-32" mousemove 75 784 click 1; sleep 3
act "exposure-press" mousemove 76 833 mousedown 1
for x in $(seq 82 6 199); do act "exposure-drag" mousemove "$x" 833; sleep 0.05; done
act "exposure-release" mouseup 1; sleep 1
act "ctrl+z" key ctrl+z; sleep 2
import -window root "$work/before_cancel.png" 2>/dev/null
for k in 1 2 3; do act "cancel-trace-$k" mousemove 730 888 click 1; sleep 1; done
act "ghosts-combo" mousemove 52 856 click 1; sleep 0.7
act "look" mousemove 81 738 click 1; sleep 1
act "looks-tab" mousemove 1112 37 click 1
looks_clicked=$(date +%s.%N)
# The window left alone while the bake runs: the UI thread's CPU over 20 s.
sleep 5
ticks() { awk '{print $14 + $15}' /proc/$app/task/$app/stat; }
t0=$(ticks); c0=$(awk '{print $14 + $15}' /proc/$app/stat); s0=$(date +%s.%N)
sleep 20
t1=$(ticks); c1=$(awk '{print $14 + $15}' /proc/$app/stat); s1=$(date +%s.%N)
hz=$(getconf CLK_TCK)
# Then a light touch every 2 s (a pointer move over the panel: a repaint) until the LUT is shown.
for _ in $(seq 1 300); do
    grep -q "lut-shown" "$work/frames.txt" 2>/dev/null && break
    act "pointer" mousemove $((1100 + RANDOM % 200)) $((300 + RANDOM % 300)); sleep 2
done
for _ in 1 2 3; do act "pointer-after" mousemove $((1100 + RANDOM % 200)) 400; sleep 1; done
import -window root "$work/landed.png" 2>/dev/null
hwm=$(awk '/VmHWM/ {print $2}' /proc/$app/status)
kill $app; sleep 1; kill $xvfb 2>/dev/null
python3 - "$work" "$looks_clicked" "$t0" "$t1" "$s0" "$s1" "$hz" "$c0" "$c1" "$hwm" <<'PY'
import sys, statistics
w, looks_clicked, t0, t1, s0, s1, hz, c0, c1, hwm = sys.argv[1:]
frames, events, painted = [], {}, []
for line in open(f"{w}/frames.txt"):
    kind, at, rest = line.split(" ", 2)
    if kind == "frame":
        frames.append((float(at), float(rest.split()[0])))
        painted.append(float(rest.split()[1]))
    else:
        events.setdefault(rest.strip(), float(at))
frames.sort()
waits = []
for line in open(f"{w}/inputs.txt"):
    at, what = line.split(" ", 1)
    at = float(at)
    answer = next(((s + ms / 1e3) for s, ms in frames if s + ms / 1e3 >= at), None)
    waits.append(((answer - at) * 1e3 if answer else float("inf"), what.strip()))
worst = max(waits)
print(f"inputs: {len(waits)}, answered in median {statistics.median(w for w, _ in waits):.0f} ms, "
      f"the slowest {worst[0]:.0f} ms ({worst[1]})")
print(f"UI frames: {len(frames)}, the slowest {max(ms for _, ms in frames):.0f} ms of the app's own work, "
      f"{max(painted):.0f} ms with its painting (eframe's cpu_usage)")
span = float(s1) - float(s0)
print(f"idle with the bake running: UI thread {100 * (int(t1) - int(t0)) / int(hz) / span:.1f} % of a core, "
      f"the whole process {100 * (int(c1) - int(c0)) / int(hz) / span:.0f} %")
if "looks-ready" in events:
    print(f"the looks' thumbnails, beside the bake: all made {events['looks-ready'] - float(looks_clicked):.1f} s after the tab opened")
else:
    print("the looks' thumbnails: not all made")
if "lut-shown" in events:
    print(f"the bake landed {events['lut-shown'] - frames[0][0]:.0f} s after the first frame")
else:
    print("the bake did not land")
rss = [int(l) for l in open(f"{w}/rss.txt") if l.strip()]
print(f"memory: RSS at most {max(rss) / 1e6:.2f} GB sampled, peak (VmHWM) {int(hwm) / 1e6:.2f} GB")
PY
echo "screenshots and records: $work"
grep -v "^$" "$work/app.log" | head -5
