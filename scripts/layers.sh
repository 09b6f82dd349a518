#!/usr/bin/env bash
# Checks that data flows one way through src/: lists the crate:: imports of every top-level
# module and fails if one imports a module on its own layer or above (the order of src/lib.rs
# and README's Layout), or if two files of one module import each other. Unit-test modules
# (a file's trailing `#[cfg(test)] mod`) are not counted.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
python3 - "$@" <<'PY'
import pathlib, re, sys

# Lowest first; modules on one line are peers and must not import each other.
LAYERS = [
    "geometry fabric compute progress preview build_id",
    "rig",
    "body",
    "io",
    "motion garment",
    "metrics",
    "models",
    "train eval simulate rollout interpolate",
    "bake compare",
    "validate",
    "batch",
    "cli",
]
layer = {m: i for i, line in enumerate(LAYERS) for m in line.split()}
src = pathlib.Path("src")
uses = {}      # top-level module -> {imported top-level module: first place}
file_uses = {} # file path (module path) -> set of sibling module paths it imports
bad = []
for f in sorted(src.rglob("*.rs")):
    rel = f.relative_to(src)
    if rel.name in ("lib.rs", "main.rs") and len(rel.parts) == 1:
        continue
    top = rel.parts[0].removesuffix(".rs")
    if top not in layer:
        bad.append(f"{f}: module '{top}' has no layer in scripts/layers.sh")
        continue
    parts = [p.removesuffix(".rs") for p in rel.parts]
    if parts[-1] == "mod":
        parts = parts[:-1]
    me = "::".join(parts)
    lines = f.read_text().splitlines()
    for n, line in enumerate(lines, 1):
        # A file's unit tests (the trailing `#[cfg(test)] mod`) may use any layer's fixtures.
        if line.startswith("#[cfg(test)]") and n < len(lines) and lines[n].startswith("mod "):
            break
        code = line.split("//")[0]
        for path in re.findall(r"\bcrate::((?:[a-z_][a-z0-9_]*::?)+)", code):
            segs = [s for s in path.split("::") if s]
            target = segs[0]
            if target == top:
                # Sibling files of one module: record file-level edges for the cycle check.
                if len(segs) >= 2:
                    file_uses.setdefault(me, set()).add("::".join(segs[:2]))
                continue
            uses.setdefault(top, {}).setdefault(target, f"{f}:{n}")
            if target in layer and layer[target] >= layer[top]:
                bad.append(f"{f}:{n}: {top} (layer {layer[top] + 1}) imports {target} (layer {layer[target] + 1})")
for a, targets in file_uses.items():
    for b in targets:
        if b != a and not b.startswith(a + "::") and a in file_uses.get(b, set()):
            if a < b:
                bad.append(f"{a} and {b} import each other")
for i, line in enumerate(LAYERS):
    for m in line.split():
        deps = sorted(uses.get(m, {}), key=lambda d: (layer.get(d, 99), d))
        print(f"{i + 1:>2} {m:<9} imports: {', '.join(deps) or '-'}")
if bad:
    print("\nimports against the layer order:", *bad, sep="\n  ", file=sys.stderr)
    sys.exit(1)
print("ok: every import points to a lower layer")
PY
