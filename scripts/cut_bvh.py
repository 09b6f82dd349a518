#!/usr/bin/env python3
"""Cut chosen frames of a BVH clip into a new BVH (same skeleton, same frame time).

The frames come from a list (--frames 3,17,40) or from a garmentbake JSON report: the frames a
`bake --json` (or `eval --json`) found beyond the model's trained range, i.e. the poses the model
never saw anything like (docs/pbns.md, "the held-out clip"). Frame numbers are the report's, so
run that command without --fps (frames at the clip's own rate) before cutting with it.

  garmentbake bake --model M --motion samples/motions/131_02.bvh --out x.glb --json > bake.json
  python3 scripts/cut_bvh.py samples/motions/131_02.bvh held_out.bvh --beyond-in bake.json

The output is written atomically (temporary file, then rename). Exits 2 with one `error:` line
on bad input.
"""
import argparse
import json
import os
import sys
import tempfile


def fail(message):
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def read_bvh(path):
    """(header lines up to MOTION inclusive, frame time line, frame lines)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as e:
        fail(f"{path}: cannot read ({e.strerror})")
    except UnicodeDecodeError:
        fail(f"{path}: not a text BVH file")
    try:
        motion = next(i for i, l in enumerate(lines) if l.strip() == "MOTION")
    except StopIteration:
        fail(f"{path}: no MOTION section")
    if motion + 2 >= len(lines) or not lines[motion + 1].strip().startswith("Frames:"):
        fail(f"{path}: MOTION is not followed by 'Frames:' and 'Frame Time:'")
    try:
        count = int(lines[motion + 1].split(":", 1)[1])
    except ValueError:
        fail(f"{path}: bad frame count line '{lines[motion + 1].strip()}'")
    time = lines[motion + 2]
    if not time.strip().startswith("Frame Time:"):
        fail(f"{path}: missing 'Frame Time:' after the frame count")
    frames = [l for l in lines[motion + 3:] if l.strip()]
    if len(frames) != count:
        fail(f"{path}: declares {count} frames but holds {len(frames)}")
    return lines[: motion + 1], time, frames


def write_atomically(path, lines):
    """The lines as a text file under `path`: a temporary sibling, then a rename."""
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".bvh.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write("\n".join(lines) + "\n")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's file is private; the clip is an ordinary file
        os.replace(tmp, path)
    except OSError as e:
        os.unlink(tmp)
        fail(f"{path}: cannot write ({e.strerror})")


def beyond_frames(report_path, clip):
    """The frames beyond the trained range in a bake or eval JSON report (the clip's, for bake)."""
    try:
        with open(report_path, encoding="utf-8") as f:
            report = json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{report_path}: cannot read a JSON report ({e})")
    coverage = report.get("coverage")
    if isinstance(coverage, dict):  # eval: one clip
        return coverage["beyond"]
    if isinstance(coverage, list):  # bake: one entry per clip
        for c in coverage:
            if c.get("clip") == clip:
                return c["beyond"]
        names = ", ".join(c.get("clip", "?") for c in coverage)
        fail(f"{report_path}: no coverage for clip '{clip}' (has: {names})")
    fail(f"{report_path}: no coverage in this report (a model trained before the coverage report?)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input", help="source BVH")
    ap.add_argument("output", help="BVH to write")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--frames", help="comma-separated frame numbers (0-based)")
    src.add_argument("--beyond-in", metavar="REPORT.json",
                     help="take the frames beyond the trained range from a bake/eval --json report")
    args = ap.parse_args()

    header, time, frames = read_bvh(args.input)
    if args.frames is not None:
        try:
            picked = [int(x) for x in args.frames.split(",") if x.strip()]
        except ValueError:
            fail(f"--frames: not a list of frame numbers: '{args.frames}'")
    else:
        clip = os.path.splitext(os.path.basename(args.input))[0]
        picked = beyond_frames(args.beyond_in, clip)
    if not picked:
        fail("no frames to cut (the report lists no frame beyond the trained range)")
    bad = [f for f in picked if not 0 <= f < len(frames)]
    if bad:
        fail(f"{args.input}: frame {bad[0]} out of range (0..{len(frames) - 1})")
    picked = sorted(set(picked))

    out = header + [f"Frames: {len(picked)}", time] + [frames[f] for f in picked]
    write_atomically(args.output, out)
    print(f"wrote {args.output}: {len(picked)} of {len(frames)} frames of {args.input} ({picked[:8]}{' …' if len(picked) > 8 else ''})")


if __name__ == "__main__":
    main()
