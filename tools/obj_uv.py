"""A plain OBJ parser's view of a garment's UVs, shared by the cache readers in tools/abc and
tools/usd (each compares the UVs a file carries with the OBJ's own)."""


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
