#!/usr/bin/env python3
"""Make new training motion from a BVH clip: its mirror image, a faster or slower take, the clip
played backwards, and/or its legs and spine swayed away from the capture.

The dynamic model learns from cloth simulations of the clips it is given, and a studio rarely
has many clips per character. A mirrored clip (left and right swapped, the motion reflected
through the body's sagittal plane) and the same clip played 0.8× or 1.25× as fast are new,
plausible motions whose simulations show the garment other swings and lags (docs/dynamic.md,
"more simulated clips").

  python3 scripts/augment_bvh.py samples/motions/131_01.bvh runs/aug/131_01_m.bvh --mirror
  python3 scripts/augment_bvh.py samples/motions/01_01.bvh runs/aug/01_01_s125.bvh --speed 1.25

Mirror: reflection x → −x of the BVH's frame (CMU skeletons: x is the body's left). Each joint
takes the channels of its counterpart (Left*/Right*, L*/R* with a capital next); a rotation R
becomes M R M with M = diag(−1, 1, 1), i.e. angles about Y and Z change sign, about X not; the
root's Xposition changes sign. This needs a left/right symmetric rest skeleton, checked: a
counterpart's OFFSET must be the mirror of the joint's within 20 % of its length (CMU's are within
a few %). Speed: frame i of the output is the source at time i·speed·frame_time, channels
interpolated linearly (angles unwrapped first, so ±180° does not spin), same frame time.
Reverse: the frames in the opposite order (the cloth then lags the other way).
Sway (`--sway SEED`, `--sway-deg A`): smooth random offsets, seeded, added to the capture's angles
of the thighs, knees, lower spine and the root's heading, so the legs reach stances the capture
never held (wider, narrower, more bent, turned). Each offset is a sum of three sines with periods
of 1–4 s and random phases, scaled to peak at about A degrees (default 20): thighs ±A forwards
and about their axis, and 0..A/2 outwards only (inwards the legs would pass through each other,
further out a long skirt could not follow);
knees 0..A more bent only (never hyper-extended); lower spine ±A/3; heading ±A/2. Joints are found
by either CMU naming (MotionBuilder `LeftUpLeg`/`LeftLeg`, 3dsMax `LeftHip`/`LeftKnee`); a
skeleton with neither is refused. Order: mirror, speed, reverse, sway.

The output is written atomically. Exits 2 with one `error:` line on bad input.
"""
import argparse
import math
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cut_bvh import fail, read_bvh, write_atomically  # noqa: E402  (scripts/' one BVH reader and writer)


def joints(header):
    """[(name, offset, channel names)] in the order their channels appear in a frame line."""
    out, name, offset = [], None, None
    for line in header:
        t = line.split()
        if not t:
            continue
        if t[0] in ("ROOT", "JOINT"):
            name, offset = t[1], None
        elif t[0] == "End":
            name = None
        elif t[0] == "OFFSET" and name is not None and offset is None:
            offset = [float(v) for v in t[1:4]]
        elif t[0] == "CHANNELS" and name is not None:
            out.append((name, offset or [0.0, 0.0, 0.0], t[2:2 + int(t[1])]))
    return out


def counterpart(name):
    for a, b in (("Left", "Right"), ("Right", "Left")):
        if name.startswith(a):
            return b + name[len(a):]
    if len(name) > 1 and name[0] in "LR" and name[1].isupper():
        return ("R" if name[0] == "L" else "L") + name[1:]
    return None


def mirror_plan(path, skeleton):
    """Per output channel: (source channel index, sign)."""
    start, index = 0, {}
    for name, offset, channels in skeleton:
        index[name] = (start, offset, channels)
        start += len(channels)
    plan = [None] * start
    for name, offset, channels in skeleton:
        other = counterpart(name)
        if other is not None and other not in index:
            other = None
        src_start, src_offset, src_channels = index[other or name]
        if src_channels != channels:
            fail(f"{path}: {name} and {other} have different channels")
        length = math.sqrt(sum(v * v for v in offset))
        mirrored = [-src_offset[0], src_offset[1], src_offset[2]]
        if math.dist(mirrored, offset) > 0.2 * max(length, 1e-9) and length > 0:
            fail(f"{path}: the skeleton is not left/right symmetric at {name} "
                 f"(offset {offset} vs its mirror {mirrored})")
        own = index[name][0]
        for k, ch in enumerate(channels):
            flip = ch in ("Yrotation", "Zrotation", "Xposition")
            plan[own + k] = (src_start + k, -1.0 if flip else 1.0)
    return plan


def parse_frames(path, frames, width):
    rows = []
    for i, line in enumerate(frames):
        try:
            row = [float(v) for v in line.split()]
        except ValueError:
            fail(f"{path}: frame {i} holds a value that is not a number")
        if len(row) != width:
            fail(f"{path}: frame {i} has {len(row)} values, the skeleton {width} channels")
        rows.append(row)
    return rows


def unwrap(column):
    out, shift = [column[0]], 0.0
    for prev, cur in zip(column, column[1:]):
        d = cur - prev
        shift -= 360.0 * round(d / 360.0)
        out.append(cur + shift)
    return out


def resample(rows, channels, speed):
    """Rows at times i·speed (in source frames), linear between source frames."""
    columns = [list(c) for c in zip(*rows)]
    columns = [unwrap(c) if ch.endswith("rotation") else c for c, ch in zip(columns, channels)]
    count = int(math.floor((len(rows) - 1) / speed)) + 1
    out = []
    for i in range(count):
        t = i * speed
        a = min(int(t), len(rows) - 1)
        b = min(a + 1, len(rows) - 1)
        w = t - a
        out.append([c[a] * (1 - w) + c[b] * w for c in columns])
    return out


# Sway roles: joint names (both CMU namings) → (role, side); side is the sign of Z that spreads the legs.
SWAY_JOINTS = {
    "LeftUpLeg": ("thigh", 1), "LeftHip": ("thigh", 1),
    "RightUpLeg": ("thigh", -1), "RightHip": ("thigh", -1),
    "LeftLeg": ("knee", -1), "LeftKnee": ("knee", -1),
    "RightLeg": ("knee", 1), "RightKnee": ("knee", 1),
    "LowerBack": ("spine", 0), "lowerback": ("spine", 0),
    "Hips": ("root", 0),
}


def smooth_noise(rng, times):
    """A sum of three sines with periods 1–4 s and random phases, peaking near ±1."""
    waves = [(rng.uniform(1.0, 4.0), rng.uniform(0.0, 2 * math.pi)) for _ in range(3)]
    return [sum(math.sin(2 * math.pi * t / period + phase) for period, phase in waves) / 2.2
            for t in times]


def sway_offsets(rng, role, side, channel, amplitude, times):
    """Degrees to add to one channel over time; None where the role leaves the channel alone."""
    if not channel.endswith("rotation"):
        return None
    axis = channel[0]
    # Drawn for every rotation channel of a swayed joint, used or not, so one seed's offsets
    # stay the same clip whatever a role leaves alone (the simulated takes depend on it).
    noise = smooth_noise(rng, times)
    one_sided = [0.5 + 0.5 * max(-1.0, min(1.0, n)) for n in noise]  # 0..1
    if role == "thigh":
        if axis == "Z":
            return [side * amplitude / 2 * u for u in one_sided]
        return [amplitude * n for n in noise]
    if role == "knee":
        return [amplitude * u for u in one_sided] if axis == "X" else None
    if role == "spine":
        return [amplitude / 3 * n for n in noise]
    if role == "root":
        return [amplitude / 2 * n for n in noise] if axis == "Y" else None
    return None


def sway(path, rows, skeleton, seed, amplitude, frame_time):
    rng = random.Random(seed)
    times = [i * frame_time for i in range(len(rows))]
    start, touched = 0, 0
    for name, _, channels in skeleton:
        role, side = SWAY_JOINTS.get(name, (None, 0))
        for k, ch in enumerate(channels):
            offsets = sway_offsets(rng, role, side, ch, amplitude, times) if role else None
            if offsets is not None:
                touched += 1
                for row, d in zip(rows, offsets):
                    row[start + k] += d
        start += len(channels)
    if touched == 0:
        fail(f"{path}: --sway found no thigh, knee, spine or root joint (CMU names expected)")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input", help="source BVH")
    ap.add_argument("output", help="BVH to write")
    ap.add_argument("--mirror", action="store_true", help="swap left and right (reflect x)")
    ap.add_argument("--speed", type=float, default=1.0, help="play rate, e.g. 0.8 or 1.25 (default 1)")
    ap.add_argument("--reverse", action="store_true", help="play the clip backwards")
    ap.add_argument("--sway", type=int, metavar="SEED", help="sway the legs and spine (seeded)")
    ap.add_argument("--sway-deg", type=float, default=20.0, metavar="A",
                    help="peak sway in degrees (default 20)")
    args = ap.parse_args()
    if not args.mirror and args.speed == 1.0 and not args.reverse and args.sway is None:
        fail("nothing to do: give --mirror, --speed, --reverse and/or --sway")
    if not 0.0 < args.sway_deg <= 45.0:
        fail(f"--sway-deg {args.sway_deg}: expected more than 0 and at most 45")
    if not 0.1 <= args.speed <= 10.0:
        fail(f"--speed {args.speed}: expected 0.1 to 10")

    header, time, frames = read_bvh(args.input)
    skeleton = joints(header)
    channels = [c for _, _, chs in skeleton for c in chs]
    rows = parse_frames(args.input, frames, len(channels))
    if args.mirror:
        plan = mirror_plan(args.input, skeleton)
        rows = [[row[src] * sign for src, sign in plan] for row in rows]
    if args.speed != 1.0:
        rows = resample(rows, channels, args.speed)
    if args.reverse:
        rows = rows[::-1]
    if args.sway is not None:
        frame_time = float(time.split(":", 1)[1])
        rows = sway(args.input, rows, skeleton, args.sway, args.sway_deg, frame_time)
    body = [" ".join(f"{v:.5f}" for v in row) for row in rows]
    write_atomically(args.output, header + [f"Frames: {len(rows)}", time] + body)
    what = ", ".join(w for w in ("mirrored" if args.mirror else "",
                                 f"at {args.speed}× speed" if args.speed != 1.0 else "",
                                 "reversed" if args.reverse else "",
                                 f"swayed (seed {args.sway}, {args.sway_deg:g}°)" if args.sway is not None else "") if w)
    print(f"wrote {args.output}: {args.input} {what}, {len(rows)} frames")


if __name__ == "__main__":
    main()
