"""A plain OBJ parser's view of a garment's UVs, and a file's UVs checked against it: shared by
the cache readers in tools/abc and tools/usd (each compares the UVs a file carries with the
OBJ's own)."""


def obj_pairs(path):
    """The OBJ's (vertex, UV) corner pairs, 0-based, as a map vertex -> its distinct UVs."""
    vt, pairs = [], {}
    with open(path) as fh:
        for line in fh:
            w = line.split()
            if not w:
                continue
            if w[0] == "vt":
                vt.append((float(w[1]), float(w[2])))
            elif w[0] == "f":
                for corner in w[1:]:
                    parts = corner.split("/")
                    v, t = int(parts[0]) - 1, int(parts[1]) - 1
                    uvs = pairs.setdefault(v, [])
                    if vt[t] not in uvs:
                        uvs.append(vt[t])
    return pairs


def compare_uvs(corners, obj):
    """`corners`: (vertex, (u, v)) per face corner of the file, against the OBJ's pairs."""
    worst, unmatched, covered = 0.0, 0, set()
    for v, uv in corners:
        options = obj.get(v, [])
        if not options:
            unmatched += 1
            continue
        d, k = min((max(abs(uv[0] - o[0]), abs(uv[1] - o[1])), k) for k, o in enumerate(options))
        worst = max(worst, d)
        if d > 1e-6:
            unmatched += 1
        else:
            covered.add((v, k))
    total = sum(len(o) for o in obj.values())
    return {"corners": len(corners), "unmatched": unmatched, "uncovered": total - len(covered),
            "obj_pairs": total, "max_uv_diff": worst}
