#!/usr/bin/python3
"""Evaluation report of catpaq (see scripts/report/run.sh, which calls this).

  report.py paths --mesh MESH.ply --out DIR [--kind bunny|scan]
      writes DIR/path_NAME.json and DIR/path_NAME_first.json (camera paths for catpaq render):
      orbit and zoom, and for a scan-like mesh a fly-through too
  report.py compare --ref DIR --frames DIR --out FILE
      per frame image error (PSNR, mean absolute difference) of DIR/frame_*.png against the reference
  report.py write --raw RAWDIR --work WORKDIR --docs DOCSDIR
      parses the tools' raw outputs and writes DOCSDIR/RESULTS.md and DOCSDIR/results/*.png

Needs matplotlib (use /usr/bin/python3).
"""
import argparse
import json
import math
import os
import re
import shutil
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import report_formats  # noqa: E402  (sections 6 and 7)

# ------------------------------------------------------------------------------------------
# camera paths


PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply_positions(path):
    """Vertex positions (n x 3 float64 numpy array) of a binary little-endian PLY whose vertex
    element comes first and has only scalar properties (as our write_ply writes)."""
    import numpy as np
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            line = f.readline()
            if not line:
                raise ReportError("no end_header in " + path)
            header += line
        lines = header.decode("ascii").splitlines()
        if "format binary_little_endian 1.0" not in lines:
            raise ReportError(path + ": only binary little-endian PLY is supported")
        n, fields, in_vertex, seen_vertex = 0, [], False, False
        for l in lines:
            p = l.split()
            if p[:2] == ["element", "vertex"]:
                if seen_vertex or fields:
                    raise ReportError(path + ": the vertex element must come first")
                n, in_vertex, seen_vertex = int(p[2]), True, True
            elif p and p[0] == "element":
                in_vertex = False
            elif in_vertex and p[0] == "property":
                if p[1] == "list" or p[1] not in PLY_TYPES:
                    raise ReportError(path + ": unsupported vertex property " + l)
                fields.append((p[2], "<" + PLY_TYPES[p[1]]))
        data = np.frombuffer(f.read(n * np.dtype(fields).itemsize), dtype=np.dtype(fields), count=n)
    return np.stack([data["x"], data["y"], data["z"]], axis=1).astype(np.float64)


def norm(v):
    l = math.sqrt(sum(c * c for c in v))
    return [c / l for c in v]


def frustum_fraction(pts, frame, width=640, height=480, fov=45.0):
    """Fraction of the points inside a camera frame's view frustum (no occlusion): what a perfectly
    view-dependent client would need at most, to compare with what it fetched."""
    import numpy as np
    e, t = np.array(frame["eye"], float), np.array(frame["target"], float)
    f = (t - e) / np.linalg.norm(t - e)
    r = np.cross(f, np.array(frame["up"], float))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = pts - e
    z = d @ f
    ty = math.tan(math.radians(fov / 2))
    tx = ty * width / height
    inside = (z > 0) & (abs(d @ r) <= tx * z) & (abs(d @ u) <= ty * z)
    return float(inside.mean())


def write_path(out, name, frames, width=640, height=480):
    with open(os.path.join(out, "path_%s.json" % name), "w") as f:
        json.dump({"width": width, "height": height, "fov": 45, "frames": frames}, f)
    # The first and the last frame alone: a cold start on one view, rendered until it converges.
    with open(os.path.join(out, "path_%s_first.json" % name), "w") as f:
        json.dump({"width": width, "height": height, "fov": 45, "frames": frames[:1]}, f)
    with open(os.path.join(out, "path_%s_last.json" % name), "w") as f:
        json.dump({"width": width, "height": height, "fov": 45, "frames": frames[-1:]}, f)


def make_paths(mesh, out, kind):
    """Camera paths for `catpaq render --camera-path`. kind "bunny": orbit and zoom to an ear tip
    (y up). kind "scan" (make_scan_like: y is the long axis, +z the front): orbit, zoom to a
    detail on the front, and a fly-through skimming the front from bottom to top."""
    pts = read_ply_positions(mesh)
    lo, hi = pts.min(axis=0).tolist(), pts.max(axis=0).tolist()
    centre = [(lo[i] + hi[i]) / 2 for i in range(3)]
    diag = math.dist(lo, hi)
    up = [0, 1, 0]
    names = []
    # orbit: 36 frames around the y axis
    frames = []
    r = (1.3 if kind == "bunny" else 0.9) * diag
    for k in range(36):
        a = 2 * math.pi * k / 36
        eye = [centre[0] + r * math.sin(a), centre[1] + 0.25 * diag, centre[2] + r * math.cos(a)]
        frames.append({"eye": eye, "target": centre, "up": up})
    write_path(out, "orbit", frames)
    names.append("orbit")
    # zoom: distance from 2.5 to 0.02 diagonals (geometric), then 12 frames holding the closest
    # view so refinement can catch up
    if kind == "bunny":
        tip = pts[pts[:, 1].argmax()].tolist()  # the tip of an ear: the vertex of largest y
        d = norm([0.35, 0.25, 1.0])
        what = "zoom target (ear tip)"
    else:
        band = pts[(abs(pts[:, 0] - centre[0]) < 0.1 * diag) & (abs(pts[:, 1] - centre[1] - 0.1 * diag) < 0.05 * diag)]
        tip = band[band[:, 2].argmax()].tolist()  # the front-most point of a band above the middle
        d = norm([0.3, 0.2, 1.0])
        what = "zoom target (front detail)"
    frames = []
    n = 40
    # The bunny's zoom ends closer than its finest level can serve at 1.5 px (on purpose: the
    # certified error shows it); the scan's ends at 0.1 diagonals, where the finest level can.
    far, near = 2.5 * diag, (0.02 if kind == "bunny" else 0.1) * diag
    for k in range(n + 12):
        t = min(k, n - 1) / (n - 1)
        dist = far * (near / far) ** t
        eye = [tip[i] + dist * d[i] for i in range(3)]
        frames.append({"eye": eye, "target": list(tip), "up": up})
    write_path(out, "zoom", frames)
    names.append("zoom")
    fly = ""
    if kind == "scan":
        # fly-through: 48 frames from 0.05 to 0.6 of the height, the eye 0.15 diagonals in front of
        # the surface (where the finest level still meets 1.5 px on a 2M-triangle scan), looking
        # 0.3 diagonals ahead along it (y1 + 0.3 diagonals stays below the top)
        frames = []
        near_axis = pts[abs(pts[:, 0] - centre[0]) < 0.05 * diag]

        def front(y):
            band = near_axis[abs(near_axis[:, 1] - y) < 0.02 * diag]
            require(len(band) > 0, "fly-through: no surface near y=%g" % y)
            return band[:, 2].max()
        m = 48
        y0, y1 = lo[1] + 0.05 * (hi[1] - lo[1]), lo[1] + 0.6 * (hi[1] - lo[1])
        for k in range(m):
            y = y0 + (y1 - y0) * k / (m - 1)
            ahead = y + 0.3 * diag
            eye = [centre[0], y, front(y) + 0.15 * diag]
            target = [centre[0], ahead, front(ahead)]
            frames.append({"eye": eye, "target": target, "up": [0, 0, 1]})
        write_path(out, "fly", frames)
        names.append("fly")
        fly = ", fly-through y %.4g -> %.4g at 0.15 diagonals from the front" % (y0, y1)
    print("bbox diagonal %.6g, centre %s, %s %s, zoom distance %.4g -> %.4g%s"
          % (diag, fmt_vec(centre), what, fmt_vec(tip), far, near, fly))
    print("paths: " + " ".join(names))
    for name in names:
        with open(os.path.join(out, "path_%s.json" % name)) as f:
            frames = json.load(f)["frames"]
        print("in_frustum %s first %.4f last %.4f" % (name, frustum_fraction(pts, frames[0]),
                                                     frustum_fraction(pts, frames[-1])))


SCAN_PATHS = ("orbit", "zoom", "fly")


def compare_frames(ref_dir, frames_dir, out):
    """Per frame: PSNR (RGB, 8 bits) and mean absolute difference of frames_dir/frame_NNNN.png
    against ref_dir/frame_NNNN.png; one JSON line per frame to `out`."""
    import numpy as np
    from PIL import Image
    names = sorted(n for n in os.listdir(ref_dir) if n.startswith("frame_") and n.endswith(".png"))
    require(names, "no reference frames in " + ref_dir)
    lines = []
    for k, n in enumerate(names):
        fp = os.path.join(frames_dir, n)
        require(os.path.exists(fp), "missing frame " + fp)
        a = np.asarray(Image.open(os.path.join(ref_dir, n)).convert("RGB"), dtype=np.float64)
        b = np.asarray(Image.open(fp).convert("RGB"), dtype=np.float64)
        require(a.shape == b.shape, "%s: size differs from the reference" % n)
        mse = float(((a - b) ** 2).mean())
        psnr = 99.0 if mse == 0 else min(99.0, 10 * math.log10(255.0 ** 2 / mse))
        lines.append(json.dumps({"frame": k, "psnr": round(psnr, 3), "mad": round(float(abs(a - b).mean()), 4),
                                 "differing_pixels": int((abs(a - b).max(axis=2) > 0).sum())}))
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("%d frames compared" % len(names))


def fmt_vec(v):
    return "(" + ", ".join("%.4g" % c for c in v) + ")"


# ------------------------------------------------------------------------------------------
# parsers


class ReportError(Exception):
    """A measurement the report needs is missing or unreadable: the run fails (exit 1)."""


def require(cond, what):
    if not cond:
        raise ReportError(what)


def read(path, default=""):
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return default


def parse_kv(text):
    out = {}
    for l in text.splitlines():
        if ":" in l:
            k, v = l.split(":", 1)
            out[k.strip()] = v.strip()
    return out


def parse_verify(text):
    """Rows of the per-level table of catpaq verify --mesh."""
    res = {"levels": [], "ok": "verify: OK" in text, "text": text}
    m = re.search(r"bounding-box diagonal ([0-9.eE+-]+)", text)
    res["diag"] = float(m.group(1)) if m else float("nan")
    m = re.search(r"dataset:\s+(\S+): (\d+) bytes, (\d+) diamonds, (\d+) fragments, (\d+) triangles", text)
    if m:
        res.update(bytes=int(m.group(2)), diamonds=int(m.group(3)), fragments=int(m.group(4)),
                   triangles=int(m.group(5)))
    m = re.search(r"^checks:\s+(.*)$", text, re.M)
    res["checks"] = m.group(1) if m else "?"
    num = r"([0-9.eE+-]+)"
    cell = r"%s \(%s\)" % (num, num)
    row = re.compile(r"^\s*(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+%s\s+%s\s+%s\s+%s\s+%s\s+%s\s*$"
                     % (num, num, cell, cell, cell, cell), re.M)
    for m in row.finditer(text):
        g = m.groups()
        res["levels"].append(dict(level=int(g[0]), diamonds=int(g[1]), triangles=int(g[2]),
                                  vertices=int(g[3]), bytes=int(g[4]), stored=float(g[5]), qstep=float(g[6]),
                                  l2o=float(g[7]), l2o_rel=float(g[8]), o2l=float(g[9]),
                                  o2l_rel=float(g[10]), l2o_rms_rel=float(g[12]), o2l_rms_rel=float(g[14])))
    return res


def parse_codec(text):
    res = {"rows": [], "text": text}
    for key, pat in [("ours_total", r"TOTAL\s+([0-9.]+) bits/vertex"),
                     ("ours_decode_ms", r"decode:\s+([0-9.]+) ms"),
                     ("ours_decode_mtri", r"decode:.*= ([0-9.]+) Mtri/s"),
                     ("ours_encode_ms", r"encode:\s+([0-9.]+) ms"),
                     ("step", r"position step ([0-9.eE+-]+)"),
                     ("precision_bits", r"equivalent precision ([0-9.]+) bits")]:
        m = re.search(pat, text)
        res[key] = m.group(1) if m else "?"
    in_table = False
    for l in text.splitlines():
        if "bits/vertex  decode ms" in l:
            in_table = True
            continue
        if in_table:
            if not l.strip() or l.strip().startswith("("):
                if l.strip().startswith("("):
                    res["note"] = l.strip()
                continue
            m = re.match(r"^\s+(.+?)\s{2,}([0-9.]+)\s+(\S+)\s*(.*)$", l)
            if m:
                rest = m.group(4).split()
                res["rows"].append(dict(name=m.group(1), bpv=m.group(2), ms=m.group(3),
                                        mtri=rest[0] if len(rest) >= 1 else "",
                                        faster=rest[1] if len(rest) >= 2 else ""))
    return res


def parse_build(text):
    rows = []
    for l in text.splitlines():
        p = l.split()
        if len(p) == 12 and re.match(r"^\d+$", p[1]):
            try:
                rows.append(dict(input=p[0], triangles=int(p[1]), seconds=float(p[2]),
                                 tps=float(p[3]), bpv=float(p[4]), mib=float(p[5]), budget=float(p[6]),
                                 spilled=float(p[7]), leaf=p[8], block=p[9],
                                 meshopt_tps=float(p[10]), ratio=float(p[11])))
            except ValueError:
                pass
    return rows


def parse_rows_after(text, header, fields, make):
    """Rows of `fields` whitespace-separated values after the line starting with `header`, each
    made into a dict by `make` (lines it cannot convert are skipped)."""
    rows = []
    in_table = False
    for l in text.splitlines():
        p = l.split()
        if l.startswith(header):
            in_table = True
            continue
        if in_table and len(p) == fields:
            try:
                rows.append(make(p))
            except ValueError:
                pass
    return rows


def parse_build_phases(text):
    """The build bench's second table: seconds per phase and cores used, per input."""
    return parse_rows_after(text, "phases (s)", 8,
                            lambda p: dict(input=p[0], phases=[float(x) for x in p[1:7]], cores=float(p[7])))


def parse_build_first_frame(text):
    """The build bench's third table: the first frame (prefix and level 0) of each dataset built."""
    return parse_rows_after(text, "first frame", 6,
                            lambda p: dict(input=p[0], nodes=int(p[1]), prefix=int(p[2]), level0=int(p[3]),
                                           total=int(p[4]), within=p[5]))


def parse_memory_budget(text, what):
    """Rows of bench/catp/memory_budget_bench: threads, budget, runs, peak min/max, max/budget, time."""
    rows = []
    for l in text.splitlines():
        m = re.match(r"^\s*(\d+)\s+(\d+)\s+(\d+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)(\s+OVER BUDGET)?\s*$", l)
        if m:
            rows.append({"threads": int(m.group(1)), "budget": int(m.group(2)), "runs": int(m.group(3)),
                         "lo": float(m.group(4)), "hi": float(m.group(5)), "ratio": float(m.group(6)),
                         "time": float(m.group(7)), "over": bool(m.group(8))})
    require(rows, what + ": no rows parsed")
    require("OK: every run stayed within its budget" in text, what + ": a run peaked past its budget")
    m = re.search(r"^input: (.*)$", text, re.M)
    return {"input": m.group(1) if m else "?", "rows": rows}


def parse_hard_cases(text):
    """Per-case lines of bench/catp/hard_cases (see its header comment)."""
    out = {"cases": [], "settings": ""}
    for l in text.splitlines():
        if l.startswith("# converter:"):
            out["settings"] = l[2:].strip()
        if not l.startswith("case|"):
            continue
        p = l.split("|")
        if len(p) != 11:
            raise ReportError("hard_cases: malformed line: " + l)
        out["cases"].append(dict(name=p[1], triangles=int(p[2]), border_in=int(p[3]), outcome=p[4],
                                 cuts=int(p[5]), border_found=int(p[6]), off_border=int(p[7]),
                                 err_rel=float(p[8]), err_over_bound=float(p[9]), detail=p[10]))
    return out


def parse_render_bench(text):
    res = {"text": text}
    for path in ("packed", "float"):
        m = re.search(r"^%s\s+best\s+([0-9.]+) ms\s+median\s+([0-9.]+) ms\s+([0-9.]+) Mtri/s \(best\)\s+"
                      r"([0-9.]+) B/vertex \(([0-9.]+) with indices\)\s+([0-9.]+) MB GPU" % path, text, re.M)
        if m:
            res[path] = dict(best=float(m.group(1)), median=float(m.group(2)), mtri=float(m.group(3)),
                             bpv=float(m.group(4)), bpv_idx=float(m.group(5)), gpu_mb=float(m.group(6)))
    for key, pat in [("dataset", r"^dataset: (.*)$"), ("gl", r"^GL: (.*)$"), ("cut", r"^finest cut: (.*)$"),
                     ("render", r"^render (.*)$"), ("ratio", r"^ratio float/packed: (.*)$"),
                     ("images", r"^images: (.*)$")]:
        m = re.search(pat, text, re.M)
        res[key] = m.group(1) if m else ""
    return res


def read_jsonl(path):
    out = []
    for l in read(path).splitlines():
        l = l.strip()
        if l:
            try:
                row = json.loads(l)
                # null: some node on screen has no data yet, so nothing bounds the error.
                if row.get("certified_error_px") is None:
                    row["certified_error_px"] = float("inf")
                out.append(row)
            except json.JSONDecodeError:
                pass
    return out


# ------------------------------------------------------------------------------------------
# plots


def plt_setup():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_rd(levels, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    cum = 0
    xs_cum, xs_bpt = [], []
    for lv in levels:
        cum += lv["bytes"]
        xs_cum.append(cum / 1024)
        xs_bpt.append(8 * lv["bytes"] / lv["triangles"])
    for key, label, mk in [("l2o_rel", "level -> original (max)", "o-"), ("o2l_rel", "original -> level (max)", "s-")]:
        ys = [lv[key] for lv in levels]
        ax[0].plot(xs_cum, ys, mk, label=label)
        ax[1].plot(xs_bpt, ys, mk, label=label)
    diag = None
    ys = [lv["stored"] for lv in levels]
    for a, xs in ((ax[0], xs_cum), (ax[1], xs_bpt)):
        for lv, x, y in zip(levels, xs, [lv["l2o_rel"] for lv in levels]):
            a.annotate("L%d" % lv["level"], (x, y), textcoords="offset points", xytext=(5, 5))
        a.set_ylabel("max distance / bbox diagonal")
        a.grid(True, alpha=0.3)
        a.legend()
    ax[0].set_xlabel("KiB to stream levels 0..L (cumulative)")
    ax[0].set_title("Bunny: error against bytes streamed")
    ax[1].set_xlabel("bits per triangle of level L (its own bytes)")
    ax[1].set_title("Bunny: error against rate of each level")
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def parse_rd(text, what):
    """rd| and bytes| lines of bench/catp/rd_bench."""
    out = {"rows": [], "vertices": 0, "levels": []}
    for l in text.splitlines():
        if l.startswith("bytes|"):
            p = l.split("|")
            if len(p) != 13:
                raise ReportError("%s: malformed line: %s" % (what, l))
            k = ["level", "nodes", "fragments", "vertices", "triangles", "bytes", "overhead", "connectivity",
                 "position", "normal", "colour", "face_vertices"]
            out["levels"].append(dict(zip(k, (int(x) for x in p[1:]))))
            continue
        if not l.startswith("rd|"):
            continue
        p = l.split("|")
        if len(p) != 13:
            raise ReportError("%s: malformed line: %s" % (what, l))
        out["rows"].append(dict(codec=p[1], setting=p[2], bytes=int(p[3]), vertices=int(p[4]), triangles=int(p[5]),
                                bpv=float(p[6]), ms=float(p[7]), mtri=float(p[8]), to_max=float(p[9]),
                                from_max=float(p[10]), to_rms=float(p[11]), from_rms=float(p[12])))
        out["vertices"] = int(p[4])
    require(any(r["codec"] == "draco" for r in out["rows"]), what + ": no Draco rows")
    require(any(r["codec"] == "meshopt" for r in out["rows"]), what + ": no meshoptimizer rows")
    require(any(r["codec"] == "catpaq" for r in out["rows"]), what + ": no catpaq decode row")
    require(out["levels"], what + ": no per-level byte breakdown")
    return out


BYTE_PARTS = ("overhead", "connectivity", "position", "normal", "colour")


def plot_level_bytes(series, outpng):
    """Bits per stored vertex by part, per level (one panel per dataset)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(series), figsize=(6 * len(series), 4), squeeze=False)
    for ax, (title, levels) in zip(axes[0], series):
        xs = [l["level"] for l in levels]
        bottom = [0.0] * len(levels)
        for part in BYTE_PARTS:
            ys = [8.0 * l[part] / max(1, l["vertices"]) for l in levels]
            ax.bar(xs, ys, bottom=bottom, label=part)
            bottom = [b + y for b, y in zip(bottom, ys)]
        ax.set_title(title)
        ax.set_xlabel("level")
        ax.set_ylabel("bits per stored vertex")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def level_table(v):
    rows, cum = [], 0
    d = v["diag"]
    for lv in v["levels"]:
        cum += lv["bytes"]
        rows.append([lv["level"], lv["diamonds"], f"{lv['triangles']:,}", f"{lv['vertices']:,}", f"{lv['bytes']:,}",
                     f"{cum:,}", "%.1f" % (8 * lv["bytes"] / lv["vertices"]), "%.1f" % (8 * cum / lv["vertices"]),
                     "%.3g" % (lv["stored"] / d), "%.3g" % (lv["qstep"] / d), "%.3g" % (lv["l2o"] / d),
                     "%.3g" % (lv["o2l"] / d), "%.2g" % lv["l2o_rms_rel"], "%.2g" % lv["o2l_rms_rel"]])
    return md_table(["level", "diamonds", "triangles", "vertices", "bytes", "cum. bytes", "bits/vertex",
                     "cum. bits/vertex", "stored error", "quant. step", "level->orig max", "orig->level max",
                     "level->orig RMS", "orig->level RMS"], rows)


def rd_rows(v, rd):
    """Rate-distortion rows of one mesh: CATP levels (cumulative bytes), then the peers."""
    out, cum = [], 0
    nv = rd["vertices"]
    d = v["diag"]
    for lv in v["levels"]:
        cum += lv["bytes"]
        out.append(dict(codec="catpaq", setting="level %d (levels 0..%d)" % (lv["level"], lv["level"]), bytes=cum,
                        bpiv=8 * cum / nv, haus=max(lv["l2o"], lv["o2l"]) / d,
                        rms=max(lv["l2o_rms_rel"], lv["o2l_rms_rel"])))
    for r in rd["rows"]:
        if r["codec"] == "catpaq":
            continue
        out.append(dict(codec=r["codec"], setting=r["setting"], bytes=r["bytes"], bpiv=8 * r["bytes"] / nv,
                        haus=max(r["to_max"], r["from_max"]), rms=max(r["to_rms"], r["from_rms"])))
    return out


def draco_at(rows, haus):
    """Draco against a CATP accuracy: the smallest setting at least as accurate, and the bytes at
    exactly that Hausdorff interpolated between the two settings around it (log Hausdorff and
    bytes linear in -qp); None where the settings do not reach it."""
    dr = sorted((r for r in rows if r["codec"] == "draco"), key=lambda r: int(r["setting"].split()[-1]))
    ok = [r for r in dr if r["haus"] <= haus]
    smallest = min(ok, key=lambda r: r["bytes"]) if ok else None
    at = None
    for a, b in zip(dr, dr[1:]):
        if a["haus"] >= haus >= b["haus"] and a["haus"] > b["haus"] > 0:
            t = math.log(a["haus"] / haus) / math.log(a["haus"] / b["haus"])
            at = a["bytes"] + t * (b["bytes"] - a["bytes"])
            break
    return smallest, at


def finest_fetch(raw, dataset, skip):
    """The stats of render's one converged frame showing the finest level everywhere."""
    rows = read_jsonl(os.path.join(raw, "finest_%s_%s.jsonl" % (dataset, skip)))
    require(len(rows) == 1, "finest_%s_%s.jsonl: expected one frame" % (dataset, skip))
    r = rows[0]
    require(r.get("settled") and "finest_level" in r.get("limited_by", []),
            "finest_%s_%s.jsonl: the view did not settle on the finest level everywhere" % (dataset, skip))
    return r


def rd_summary(rows):
    """One measured sentence: CATP's finest level against the smallest peer encoding at least as accurate."""
    ours = [r for r in rows if r["codec"] == "catpaq"]
    if not ours:
        return ""
    fin = ours[-1]
    parts = []
    for codec in ("draco", "meshopt"):
        ok = [r for r in rows if r["codec"] == codec and r["haus"] <= fin["haus"]]
        if ok:
            b = min(ok, key=lambda r: r["bytes"])
            parts.append("%s %s: %s, Hausdorff %.2g (CATP needs %.1fx its bytes)"
                         % (codec, b["setting"], fmt_bytes(b["bytes"]), b["haus"], fin["bytes"] / b["bytes"]))
    return ("On the scan-like mesh, CATP's finest level (all levels streamed: %s, Hausdorff %.2g, RMS %.2g of the "
            "diagonal) against the smallest encoding of each peer that is at least as accurate: %s. The peers "
            "are single-resolution files; CATP pays for every coarser level, for clipping into tetrahedra "
            "and for quantizing every level on the finest level's grid, and buys view-dependent streaming with it (section 3)."
            % (fmt_bytes(fin["bytes"]), fin["haus"], fin["rms"], "; ".join(parts) or "none"))


CODEC_STYLE = {"catpaq": ("o-", "tab:blue"), "draco": ("s--", "tab:red"), "meshopt": ("^:", "tab:green")}


def plot_rd_codecs(meshes, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(2, len(meshes), figsize=(6 * len(meshes), 8), squeeze=False)
    for col, (title, rows) in enumerate(meshes):
        for row, key, label in ((0, "haus", "Hausdorff / bbox diagonal"), (1, "rms", "RMS / bbox diagonal")):
            a = ax[row][col]
            for codec, (mk, color) in CODEC_STYLE.items():
                rs = [r for r in rows if r["codec"] == codec]
                if rs:
                    a.plot([r["bpiv"] for r in rs], [r[key] for r in rs], mk, color=color,
                           label={"catpaq": "CATP levels (cumulative)", "draco": "Draco -qp",
                                  "meshopt": "meshoptimizer codecs"}[codec])
                    for r in rs:
                        tag = r["setting"].split()[1] if codec != "meshopt" else r["setting"].split("-")[0]
                        a.annotate(tag, (r["bpiv"], r[key]), textcoords="offset points", xytext=(4, 3), fontsize=7)
            a.set_xscale("log")
            a.set_yscale("log")
            a.set_xlabel("bits per input vertex")
            a.set_ylabel(label)
            a.grid(True, which="both", alpha=0.3)
            a.set_title(title)
            a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def plot_decode(meshes, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(1, len(meshes), figsize=(6 * len(meshes), 4), squeeze=False)
    for col, (title, rd) in enumerate(meshes):
        a = ax[0][col]
        for codec, (mk, color) in CODEC_STYLE.items():
            rs = [r for r in rd["rows"] if r["codec"] == codec]
            if rs:
                a.plot([r["bytes"] / 1e6 for r in rs], [r["mtri"] for r in rs], mk[0], color=color, ms=8,
                       label={"catpaq": "catpaq (all nodes)", "draco": "Draco", "meshopt": "meshoptimizer"}[codec])
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("compressed MB")
        a.set_ylabel("decoded Mtriangles / s")
        a.set_title(title)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def plot_stream(streams, size, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(3, 1, figsize=(9, 9), sharex=False)
    for name, rows in streams.items():
        if not rows:
            continue
        f = [r["frame"] for r in rows]
        ax[0].plot(f, [r["triangles"] for r in rows], label=name)
        ax[1].plot(f, [r["bytes_fetched"] / 1024 for r in rows], label=name)
        ax[2].plot(f, [max(min(r["certified_error_px"], 1e6), 1e-3) for r in rows], label=name)
    if size:
        ax[1].axhline(size / 1024, color="gray", ls="--", label="whole dataset")
    ax[2].axhline(1.5, color="red", ls=":", label="tolerance 1.5 px")
    ax[0].set_ylabel("triangles drawn")
    ax[1].set_ylabel("KiB fetched so far")
    ax[2].set_ylabel("certified error (px)")
    ax[2].set_yscale("log")
    ax[2].set_xlabel("frame (one streaming step per frame, --no-converge)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend()
    ax[0].set_title("Streaming the bunny over HTTP")
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def plot_stream_scan(streams, imgerr, size, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(5, 1, figsize=(9, 14))
    for name, rows in streams.items():
        f = [r["frame"] for r in rows]
        ax[0].plot(f, [r["triangles"] for r in rows], label=name)
        ax[1].plot(f, [100 * r["bytes_fetched"] / size for r in rows], label=name)
        ax[2].plot(f, [r["pending"] for r in rows], label=name)
        ax[3].plot(f, [max(min(r["certified_error_px"], 1e6), 1e-3) for r in rows], label=name)
        ax[4].plot(f, [e["psnr"] for e in imgerr[name]], label=name)
    ax[3].axhline(1.5, color="red", ls=":", label="tolerance 1.5 px")
    for a, lab in zip(ax, ["triangles drawn", "% of dataset fetched so far", "pending requests",
                           "certified error (px)", "PSNR vs reference (dB)"]):
        a.set_ylabel(lab)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    ax[3].set_yscale("log")
    ax[4].set_xlabel("frame (one streaming step per frame, --no-converge)")
    ax[0].set_title("Streaming the scan-like dataset over HTTP")
    fig.tight_layout()
    fig.savefig(outpng, dpi=90)
    plt.close(fig)


def plot_build(rows, outpng):
    plt = plt_setup()
    fig, ax = plt.subplots(figsize=(7, 4))
    xs = [r["triangles"] for r in rows]
    ax.plot(xs, [r["tps"] / 1e3 for r in rows], "o-", label="CATP build (k tri/s)")
    ax.set_xscale("log")
    ax.set_xlabel("input triangles")
    ax.set_ylabel("k triangles / s")
    ax2 = ax.twinx()
    ax2.plot(xs, [r["mib"] for r in rows], "s--", color="tab:orange", label="peak MiB")
    if rows and "budget" in rows[0]:
        ax2.axhline(rows[0]["budget"], color="tab:red", linestyle=":", label="memory budget")
    ax2.set_ylabel("peak memory (MiB)")
    ax.grid(True, alpha=0.3)
    fig.legend(loc="upper center")
    ax.set_title("Build throughput", pad=20)
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)


def frame_strip(frames_dir, indices, outpng, titles):
    plt = plt_setup()
    import matplotlib.image as mpimg
    imgs = []
    for i, t in zip(indices, titles):
        p = os.path.join(frames_dir, "frame_%04d.png" % i)
        if os.path.exists(p):
            imgs.append((mpimg.imread(p), t))
    if not imgs:
        return False
    cols = min(3, len(imgs))
    nrows = (len(imgs) + cols - 1) // cols
    fig, ax = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.4 * nrows), squeeze=False)
    ax = list(ax.flat)
    for a in ax[len(imgs):]:
        a.axis("off")
    for a, (im, t) in zip(ax, imgs):
        a.imshow(im)
        a.set_title(t, fontsize=9)
        a.axis("off")
    fig.tight_layout()
    fig.savefig(outpng, dpi=100)
    plt.close(fig)
    return True


# ------------------------------------------------------------------------------------------
# report


def fmt_bytes(n):
    if n >= 1 << 20:
        return "%.2f MiB" % (n / (1 << 20))
    if n >= 1024:
        return "%.1f KiB" % (n / 1024)
    return "%d B" % n


md_table = report_formats.md_table  # one markdown table writer for every section


def first_ok(rows, size):
    for r in rows:
        if r["triangles"] > 0 and r["certified_error_px"] <= r["tolerance_px"]:
            return "frame %d: %s (%.0f%%)" % (r["frame"], fmt_bytes(r["bytes_fetched"]),
                                             100 * r["bytes_fetched"] / size if size else float("nan"))
    return "never"


def seconds(text):
    """'1234e-3' (as run.sh writes durations) -> '1.23'."""
    try:
        return "%.2f" % (float(text[:-3]) / 1000 if text.endswith("e-3") else float(text))
    except ValueError:
        return "?"


def write_report(raw, work, docs):
    resdir = os.path.join(docs, "results")
    os.makedirs(resdir, exist_ok=True)
    mach = parse_kv(read(os.path.join(raw, "machine.txt")))
    mode = mach.get("mode", "?")
    size = int(read(os.path.join(raw, "dataset_size.txt"), "0").strip() or 0)
    info = parse_kv(read(os.path.join(raw, "info.txt")))
    ver = parse_verify(read(os.path.join(raw, "verify.txt")))
    codec = parse_codec(read(os.path.join(raw, "codec_bench.txt")))
    build = parse_build(read(os.path.join(raw, "build_bench.txt")))
    hard = parse_hard_cases(read(os.path.join(raw, "hard_cases.txt")))
    memory = [parse_memory_budget(read(os.path.join(raw, f)), f) for f in ("memory_scan.txt", "memory_uneven.txt")]
    ver_scan = parse_verify(read(os.path.join(raw, "verify_scan.txt")))
    require(ver_scan["levels"], "verify_scan.txt: no per-level rows parsed")
    rd_bunny = parse_rd(read(os.path.join(raw, "rd_bunny.txt")), "rd_bunny.txt")
    rd_scan = parse_rd(read(os.path.join(raw, "rd_scan.txt")), "rd_scan.txt")
    rd_tris = int(mach.get("rd_triangles", "0"))
    stream_tris = int(mach.get("stream_triangles", "0"))
    codec_scan = None
    if mode == "full":
        codec_scan = parse_codec(read(os.path.join(raw, "codec_bench_scan.txt")))
        require(codec_scan["rows"], "codec_bench_scan.txt: no comparison rows parsed")
    conv_scan_s = seconds(mach.get("convert_scan_rd_seconds", "?"))
    require(ver["levels"], "verify.txt: no per-level rows parsed")
    require(codec["rows"], "codec_bench.txt: no comparison rows parsed")
    require(build, "build_bench.txt: no rows parsed")
    require(hard["cases"], "hard_cases.txt: no cases parsed")
    rb_rc = read(os.path.join(raw, "render_bench_rc.txt"), "?").strip()
    rb = parse_render_bench(read(os.path.join(raw, "render_bench.txt")))
    streams = {p: read_jsonl(os.path.join(raw, "stream_%s.jsonl" % p)) for p in ("orbit", "zoom")}
    paths_txt = read(os.path.join(raw, "paths.txt")).strip().splitlines()[0]
    scan_paths_raw = read(os.path.join(raw, "paths_scan.txt"))
    scan_paths_txt = scan_paths_raw.strip().splitlines()[0]
    in_frustum = {m.group(1): (float(m.group(2)), float(m.group(3)))
                  for m in re.finditer(r"^in_frustum (\S+) first ([0-9.]+) last ([0-9.]+)$", scan_paths_raw, re.M)}
    require(all(p in in_frustum for p in SCAN_PATHS), "paths_scan.txt: no frustum fractions")
    scan_size = int(read(os.path.join(raw, "scan_dataset_size.txt"), "0").strip() or 0)
    require(scan_size > 0, "scan_dataset_size.txt missing")
    fine_size = int(read(os.path.join(raw, "scanfine_dataset_size.txt"), "0").strip() or 0)
    require(fine_size > 0, "scanfine_dataset_size.txt missing")
    m = re.search(r"(\d+) diamonds", read(os.path.join(raw, "verify_scan_stream.txt")))
    require(m, "verify_scan_stream.txt: no node count")
    scan_nodes = int(m.group(1))
    m = re.search(r"(\d+) diamonds", read(os.path.join(raw, "verify_scan_fine.txt")))
    require(m, "verify_scan_fine.txt: no node count")
    fine_nodes = int(m.group(1))
    scan_streams, scan_cold, scan_imgerr = {}, {}, {}
    for p in SCAN_PATHS:
        scan_streams[p] = read_jsonl(os.path.join(raw, "stream_scan_%s.jsonl" % p))
        require(scan_streams[p], "stream_scan_%s.jsonl: no frames" % p)
        for ds, view in (("scan", "first"), ("scan", "last"), ("scanfine", "last")):
            cold = read_jsonl(os.path.join(raw, "cold_%s_%s_%s.jsonl" % (ds, p, view)))
            require(len(cold) == 1, "cold_%s_%s_%s.jsonl: expected one frame" % (ds, p, view))
            key = (p, view) if ds == "scan" else (p, "last, fine")
            scan_cold[key] = dict(cold[0], wall_ms=float(
                read(os.path.join(raw, "cold_%s_%s_%s_wall_ms.txt" % (ds, p, view)), "nan")),
                size=scan_size if ds == "scan" else fine_size)
        for view in ("first", "last"):
            cold = read_jsonl(os.path.join(raw, "cold_scan_%s_%s_noskip.jsonl" % (p, view)))
            require(len(cold) == 1, "cold_scan_%s_%s_noskip.jsonl: expected one frame" % (p, view))
            scan_cold[p, view + ", no skip"] = dict(cold[0], size=scan_size)
            cold = read_jsonl(os.path.join(raw, "cold_scan_%s_%s_whole.jsonl" % (p, view)))
            require(len(cold) == 1, "cold_scan_%s_%s_whole.jsonl: expected one frame" % (p, view))
            scan_cold[p, view + ", whole"] = dict(cold[0], size=scan_size)
        scan_imgerr[p] = read_jsonl(os.path.join(raw, "imgerr_scan_%s.jsonl" % p))
        require(len(scan_imgerr[p]) == len(scan_streams[p]), "imgerr_scan_%s.jsonl: one row per frame expected" % p)
    fetch_views = {}
    for j in read_jsonl(os.path.join(raw, "fetch_bench_scan.jsonl")):
        m = re.match(r"path_(\w+)_(first|last)", j["view"])
        require(m, "fetch_bench_scan.jsonl: unexpected view name %s" % j["view"])
        fetch_views[m.group(1), m.group(2)] = j
    for p in SCAN_PATHS:
        for view in ("first", "last"):
            require((p, view) in fetch_views, "fetch_bench_scan.jsonl: no %s %s view" % (p, view))
    conv_s = seconds(mach.get("convert_seconds", "?"))
    L = []
    w = L.append

    w("# catpaq: evaluation results")
    w("")
    w("Generated by `scripts/report/run.sh%s` on %s. Every figure below was measured by that run; "
      "nothing is copied from elsewhere. Re-running overwrites this file and `docs/results/*.png`."
      % (" --short" if mode == "short" else "", mach.get("date", "?")))
    w("")
    w(md_table(["machine", ""], [
        ["CPU", mach.get("cpu", "?")], ["cores", mach.get("cores", "?")],
        ["memory", mach.get("memory", "?")], ["kernel", mach.get("kernel", "?")],
        ["commit", "`%s`" % mach.get("git", "?")], ["mode", mode],
        ["run time", "%s s" % mach.get("total_seconds", "?")]]))
    w("")
    w("**Reproduce:** `scripts/build.sh` then `scripts/report/run.sh` (full: scan-like meshes of 1M "
      "and 2M triangles, build bench up to 10M triangles, builds under a 1 GiB memory budget, point clouds up to "
      "100M points, about 20 minutes) "
      "or `scripts/report/run.sh --short` (300k-triangle scan, build bench at 100k; about 2-3 minutes on "
      "2 cores; `scripts/test.sh` runs it with `--out` a temporary directory). `--out DIR` writes "
      "`DIR/RESULTS.md` and `DIR/results/` instead of `docs/`; `KEEP_RAW=1` keeps the tools' raw "
      "outputs; `BUILD=` names the build directory. The run stops with a non-zero status naming the "
      "step when a tool it needs fails. The report needs `/usr/bin/python3` with matplotlib "
      "(`PYTHON=` overrides).")
    w("")

    # headline
    w("## Headline")
    w("")
    heads = []
    if ver["levels"]:
        fin = ver["levels"][-1]
        heads.append("Bunny (%s triangles in, %s bytes as CATP, %d levels): finest level %d has max "
                     "two-sided distance %.2g of the bbox diagonal; the coarsest level (%s, %.0f%% of the "
                     "file) already %.2g." % (info.get("triangles", "?"), f"{size:,}", len(ver["levels"]),
                                              fin["level"], max(fin["l2o_rel"], fin["o2l_rel"]),
                                              fmt_bytes(ver["levels"][0]["bytes"]),
                                              100 * ver["levels"][0]["bytes"] / max(size, 1),
                                              max(ver["levels"][0]["l2o_rel"], ver["levels"][0]["o2l_rel"])))
    for name, rows in streams.items():
        if rows and size:
            last = rows[-1]
            heads.append("Streaming the bunny, %s path (%d frames): fetched %s of %s = **%.0f%% of the dataset**; "
                         "last frame %s triangles, certified error %.3g px (tolerance %.1f)."
                         % (name, len(rows), fmt_bytes(last["bytes_fetched"]), fmt_bytes(size),
                            100 * last["bytes_fetched"] / size, f"{last['triangles']:,}",
                            last["certified_error_px"], last["tolerance_px"]))
    def cold_text(c):
        return "%.0f ms and %s (%.1f%% of the dataset)%s" % (
            c["elapsed_ms"], fmt_bytes(c["bytes_fetched"]), 100 * c["bytes_fetched"] / scan_size,
            "" if c["certified_error_px"] <= c["tolerance_px"] else
            ", tolerance not reached: certified %.3g px when converged" % c["certified_error_px"])
    for p in SCAN_PATHS:
        rows = scan_streams[p]
        heads.append("Scan-like %s triangles (%s as CATP), **%s**: cold start to 1.5 px on the first view alone "
                     "**%s**, on the last view alone **%s** (%.0f%% of the input's vertices in its frustum; "
                     "%.1f%% of the dataset with 500-triangle leaves); "
                     "along the whole path (%d frames, one streaming step each) the client fetched **%.1f%% of "
                     "the dataset**; last frame %.1f dB PSNR against the 0.1 px reference."
                     % (f"{stream_tris:,}", fmt_bytes(scan_size), p, cold_text(scan_cold[p, "first"]),
                        cold_text(scan_cold[p, "last"]), 100 * in_frustum[p][1],
                        100 * scan_cold[p, "last, fine"]["bytes_fetched"] / fine_size, len(rows),
                        100 * rows[-1]["bytes_fetched"] / scan_size, scan_imgerr[p][-1]["psnr"]))
    rs = rd_rows(ver_scan, rd_scan)
    fin = [r for r in rs if r["codec"] == "catpaq"][-1]
    dr = [r for r in rs if r["codec"] == "draco" and r["haus"] <= fin["haus"]]
    heads.append("Rate-distortion, scan-like %s triangles: CATP's finest level (all levels: %.1f bits per input "
                 "vertex) has Hausdorff %.2g of the diagonal; %s" % (
                     f"{rd_tris:,}", fin["bpiv"], fin["haus"],
                     ("the smallest Draco file at least as accurate (%s) takes %.1f bits per input vertex." %
                      (min(dr, key=lambda r: r["bytes"])["setting"], min(dr, key=lambda r: r["bytes"])["bpiv"]))
                     if dr else "no Draco setting measured is as accurate."))
    cat = [r for r in rd_scan["rows"] if r["codec"] == "catpaq"][0]
    heads.append("Decode, scan-like mesh: catpaq %.1f Mtri/s (all nodes), meshoptimizer %.0f-%.0f Mtri/s, Draco "
                 "%.1f-%.1f Mtri/s." % (cat["mtri"], min(r["mtri"] for r in rd_scan["rows"] if r["codec"] == "meshopt"),
                                       max(r["mtri"] for r in rd_scan["rows"] if r["codec"] == "meshopt"),
                                       min(r["mtri"] for r in rd_scan["rows"] if r["codec"] == "draco"),
                                       max(r["mtri"] for r in rd_scan["rows"] if r["codec"] == "draco")))
    npass = sum(c["outcome"] == "passes" for c in hard["cases"])
    nref = sum(c["outcome"] == "refused" for c in hard["cases"])
    heads.append("Hard cases: %d of %d pass, %d refused with a message, %d fail (section 5)."
                 % (npass, len(hard["cases"]), nref, len(hard["cases"]) - npass - nref))
    if "packed" in rb and "float" in rb:
        heads.append("Render (llvmpipe): packed 8-byte vertices median %.1f ms vs float %.1f ms per frame."
                     % (rb["packed"]["median"], rb["float"]["median"]))
    for h in heads:
        w("- " + h)
    w("")

    # (1)
    w("## 1. Rate-distortion")
    w("")
    w("Per CATP level: `catpaq convert` (defaults), then `catpaq verify --mesh ORIGINAL`, which measures "
      "on the uniform cut at each level the distance to the original in both directions (largest and "
      "RMS over 50,000 surface samples per direction, CGAL AABB tree), relative to the bounding-box "
      "diagonal. *Bytes* are the compressed bytes of that level's nodes; *cum. bytes* what a client must "
      "fetch to show level L everywhere (levels 0..L). *Vertices* are those of the uniform cut at level "
      "L, welded; bits/vertex divides the level's own bytes (cum.: levels 0..L) by them. Stored error and "
      "quantization step are relative to the diagonal too.")
    w("")
    for key, title, v, cs, desc in (
            ("bunny", "Bunny", ver, conv_s, "`data/bunny.ply`, %s triangles" % info.get("triangles", "?")),
            ("scan", "Scan-like mesh", ver_scan, conv_scan_s,
             "`make_scan_like(%s)` with colours (written as PLY by `bench/catp/gen_mesh`)" % f"{rd_tris:,}")):
        w("### 1.%d %s: CATP levels" % (1 if key == "bunny" else 2, title))
        w("")
        w("%s; converted in %s s. Checks: %s. Verify result: **%s**. Bounding-box diagonal %.6g."
          % (desc, cs, v["checks"], "OK" if v["ok"] else "FAILED", v["diag"]))
        w("")
        w(level_table(v))
        w("")
        lv = v["levels"]
        nonmono = [b["level"] for a, b in zip(lv, lv[1:]) if b["l2o"] > a["l2o"]]
        if nonmono:
            w("The measured level->original distance is **not monotone** in the level (level %s is "
              "farther from the original than the level before it); the finest level's quantization step "
              "(%.3g of the diagonal) is of the size of the measured distance, so quantization, not "
              "simplification, bounds its accuracy." % (", ".join(map(str, nonmono)), lv[-1]["qstep"] / v["diag"]))
            w("")
    plot_rd(ver["levels"], os.path.join(resdir, "rate_distortion.png"))
    w("![rate-distortion per level (bunny)](results/rate_distortion.png)")
    w("")

    w("### 1.3 Against Draco and meshoptimizer (same meshes, same distance code)")
    w("")
    w("`bench/catp/rd_bench` encodes the same input with Draco 1.5 (`draco_encoder -qp N -qn 8 -qg 8 "
      "-cl 7`: positions, normals, colours when present) and meshoptimizer 0.18's index and vertex codecs "
      "(after its vertex cache and fetch optimisations; 12-byte vertices: positions quantised to B bits "
      "on Draco's grid, a 16-bit octahedral normal, RGB), decodes them and measures the decoded mesh "
      "against the original with verify's sampling and distance code (same original samples). A "
      "single-resolution codec's *bits per input vertex* is its file size x 8 / input vertices; for "
      "CATP level L it is the *cumulative* bytes of levels 0..L (what a client fetches to show level L "
      "everywhere) x 8 / input vertices, so all rows share the denominator. Hausdorff = the larger of "
      "the two directed maxima; RMS = the larger of the two directed RMS; both relative to the diagonal. "
      "CATP bytes include 8+8-bit normals and, for coloured inputs, RGB (8 or 6 bits per channel, the "
      "dataset's vertex layout); the colourless bunny spends the colour bits on position.")
    w("")
    for key, title, v, rd in (("bunny", "Bunny", ver, rd_bunny), ("scan", "Scan-like %s triangles" % f"{rd_tris:,}",
                                                                       ver_scan, rd_scan)):
        w("**%s** (%s input vertices):" % (title, f"{rd['vertices']:,}"))
        w("")
        w(md_table(["codec", "setting", "bytes", "bits per input vertex", "Hausdorff / diag", "RMS / diag"],
                   [[r["codec"], r["setting"], f"{r['bytes']:,}", "%.1f" % r["bpiv"], "%.3g" % r["haus"],
                     "%.3g" % r["rms"]] for r in rd_rows(v, rd)]))
        w("")
    plot_rd_codecs([("Bunny", rd_rows(ver, rd_bunny)), ("Scan-like %s tri" % f"{rd_tris:,}", rd_rows(ver_scan, rd_scan))],
                   os.path.join(resdir, "rd_codecs.png"))
    w("![rate-distortion against Draco and meshoptimizer](results/rd_codecs.png)")
    w("")
    best = rd_summary(rd_rows(ver_scan, rd_scan))
    if best:
        w(best)
        w("")

    w("**What a client fetches to show the finest level everywhere.** The cumulative rows above count "
      "every level; a client need not fetch them all. `catpaq render URL --orbit 1 --size 1600x1200 "
      "--tolerance 0.05` over HTTP from a cold start (the served datasets above; the whole model in view, "
      "so that every drawn node is a leaf: each run settled with the finest level as its limit) with "
      "the default level skipping (`--skip 8`: coarser levels drawn on the way, as a viewer shows them) "
      "and skipping every level a refinement passes at once (`--skip 1000000`: the first frame, then "
      "the leaves). *Fetched* includes the first request (prefix and level 0). Draco: the smallest "
      "setting at least as accurate as CATP's finest level (Hausdorff), and its bytes at exactly that "
      "Hausdorff, interpolated between the two settings around it (log Hausdorff and bytes linear in -qp).")
    w("")
    frows = []
    finest_ratios = []
    for title, v, rd, ds in (("bunny", ver, rd_bunny, "bunny"), ("scan %s" % f"{rd_tris:,}", ver_scan, rd_scan, "scanrd")):
        rows = rd_rows(v, rd)
        fin = [r for r in rows if r["codec"] == "catpaq"][-1]
        alone = v["levels"][-1]["bytes"]
        smallest, at = draco_at(rows, fin["haus"])
        for skip, label in ((8, "levels on the way (--skip 8)"), (1000000, "straight to the leaves (--skip 1000000)")):
            f = finest_fetch(raw, ds, skip)
            got = f["bytes_fetched"]
            if skip == 1000000:
                finest_ratios.append((title, got / smallest["bytes"] if smallest else None, got / at if at else None))
            frows.append([title, label, f"{got:,}", str(f["requests"]), f"{f['triangles']:,}", f"{alone:,}", f"{fin['bytes']:,}",
                          "%s: %s" % (smallest["setting"], f"{smallest['bytes']:,}") if smallest else "-",
                          "%.2f" % (got / smallest["bytes"]) if smallest else "-",
                          f"{at:,.0f}" if at else "-", "%.2f" % (got / at) if at else "-"])
    w(md_table(["mesh", "client", "fetched bytes", "requests", "triangles drawn", "finest level alone", "all levels",
                "Draco, smallest at least as accurate", "fetched / it", "Draco at equal Hausdorff",
                "fetched / it"], frows))
    w("")
    w("Target (issue 16): what a client fetches to show the finest level everywhere at most 2x Draco's file "
      "at equal Hausdorff, on the bunny and the scan: " +
      "; ".join("%s %s against the smallest Draco at least as accurate, %s at equal Hausdorff" %
                (t, "%.2fx" % a if a else "-", "%.2fx" % b if b else "-") for t, a, b in finest_ratios) + ".")
    w("")

    w("### 1.5 Where the bytes go, per level")
    w("")
    w("`rd_bench --cpq` re-encodes every fragment of the dataset (the encoder is deterministic) and sums "
      "the codec's per-stream sizes per level, in bits per stored vertex (a level's fragments' vertices, "
      "shared ones once per fragment): *overhead* is the fragment headers, tables and the nodes' framing; "
      "*face vertices* are the share of stored vertices on a face, edge or corner of their tetrahedron "
      "(quantized on the face's grid, shared with the neighbour).")
    w("")
    for title, rd in (("Bunny", rd_bunny), ("Scan-like %s triangles" % f"{rd_tris:,}", rd_scan)):
        w("**%s**:" % title)
        w("")
        rows = []
        for l in rd["levels"]:
            v = max(1, l["vertices"])
            rows.append([str(l["level"]), f"{l['fragments']:,}", f"{l['vertices']:,}",
                         "%.0f" % (l["triangles"] / max(1, l["fragments"])), "%.1f" % (8.0 * l["bytes"] / v)] +
                        ["%.1f" % (8.0 * l[p] / v) for p in BYTE_PARTS] + ["%.0f%%" % (100.0 * l["face_vertices"] / v)])
        w(md_table(["level", "fragments", "vertices", "triangles per fragment", "bits/vertex", "overhead",
                    "connectivity", "position", "normal", "colour", "face vertices"], rows))
        w("")
    plot_level_bytes([("Bunny", rd_bunny["levels"]), ("Scan-like %s tri" % f"{rd_tris:,}", rd_scan["levels"])],
                     os.path.join(resdir, "level_bytes.png"))
    w("![bits per stored vertex by part and level](results/level_bytes.png)")
    w("")

    w("### 1.4 Decode speed against size")
    w("")
    w("In the same run (`rd_bench`): catpaq decodes **every node** of the dataset (all levels, "
      "`CatpFile::decode`: the fragment codec on real CATP data, best of 3; its triangles are those of "
      "all levels together); meshoptimizer decodes index and vertex buffers (best of 5); Draco's time "
      "is `draco_decoder`'s own 'ms to decode' (best of 3, millisecond resolution). Mtri/s = decoded "
      "triangles per second.")
    w("")
    drows = []
    for title, rd in (("bunny", rd_bunny), ("scan %s" % f"{rd_tris:,}", rd_scan)):
        for r in rd["rows"]:
            drows.append([title, r["codec"], r["setting"], f"{r['bytes']:,}", "%.1f" % r["bpv"],
                          f"{r['triangles']:,}", "%.1f" % r["ms"], "%.1f" % r["mtri"]])
    w(md_table(["mesh", "codec", "setting", "bytes", "bits/vertex", "decoded triangles", "decode ms", "Mtri/s"], drows))
    w("")
    plot_decode([("Bunny", rd_bunny), ("Scan-like %s tri" % f"{rd_tris:,}", rd_scan)],
                os.path.join(resdir, "decode_speed.png"))
    w("![decode speed against size](results/decode_speed.png)")
    w("")

    for title, cd in (("bunny", codec), ("scan-like %s triangles" % f"{rd_tris:,}", codec_scan)):
        if cd is None:
            w("### codec_bench on the scan-like mesh")
            w("")
            w("Skipped in short mode (about 40 s on 2 cores); the full run includes it.")
            w("")
            continue
        w("### Fragment codec alone (codec_bench, %s)" % title)
        w("")
        w("codec_bench cuts the mesh into Kuhn-tetrahedron fragments itself (dropping triangles that cross "
          "a fragment, see its header) and encodes them with our fragment codec and meshoptimizer; Draco "
          "encodes the whole mesh. Each peer's speed is compared with ours on the same attributes: "
          "meshoptimizer's vertices and Draco's `-qg 8` files carry the fragments' synthetic colours, and "
          "are compared with our coloured fragments; Draco's other files have positions and normals only, "
          "and are compared with the same fragments encoded without colour (the layout a colourless input "
          "gets). Position step %s mesh units (%s bits over the diagonal); catpaq encode "
          "%s ms." % (cd["step"], cd["precision_bits"], cd["ours_encode_ms"]))
        w("")
        w(md_table(["codec", "bits/vertex", "decode ms", "Mtri/s", "catpaq decode faster by"],
                   [[r["name"], r["bpv"], r["ms"], r["mtri"], r["faster"]] for r in cd["rows"]]))
        if cd.get("note"):
            w("")
            w(cd["note"])
        w("")

    # (2)
    w("## 2. Build speed (catp_build_bench)")
    w("")
    if build:
        w(md_table(["input", "triangles", "seconds", "tri/s", "bits/vertex", "peak MiB", "budget MiB",
                    "spilled MiB", "leaf level", "block level", "meshopt_simplify tri/s", "ratio"],
                   [[r["input"], f"{r['triangles']:,}", "%.2f" % r["seconds"], f"{r['tps']:,.0f}",
                     "%.2f" % r["bpv"], "%.1f" % r["mib"], "%.0f" % r["budget"], "%.1f" % r["spilled"],
                     r["leaf"], r["block"], f"{r['meshopt_tps']:,.0f}", "%.3f" % r["ratio"]] for r in build]))
        w("")
        w("Each build converts a binary PLY file on disk, reading included, in its own process under a "
          "memory budget for the whole process (`catpaq convert --memory`); *spilled* is the scratch data "
          "the out-of-core converter wrote to disk because it did not fit the budget, *block level* the "
          "level of the spatial blocks the leaves were clipped in. "
          "ratio = full CATP build throughput / one 50%% meshopt_simplify pass (1 thread). `scanN` inputs "
          "are generated scan-like meshes.%s" % (" Short mode: 100k only; the full run adds 1M and 10M."
                                                  if mode == "short" else ""))
        w("")
        phases = parse_build_phases(read(os.path.join(raw, "build_bench.txt")))
        if phases:
            w("Where the time goes, seconds per phase (read the vertices, bin the triangles into blocks, "
              "clip the leaves, encode the leaf nodes, coarsen, write the file) and cores used (CPU time / "
              "wall time, 2 cores):")
            w("")
            w(md_table(["input", "read", "bin", "clip", "leaf nodes", "coarsen", "write", "cores used"],
                       [[r["input"]] + ["%.2f" % x for x in r["phases"]] + ["%.2f" % r["cores"]] for r in phases]))
            w("")
        first = parse_build_first_frame(read(os.path.join(raw, "build_bench.txt")))
        if first:
            w("The first frame of each dataset built (what a client fetches before it draws the whole model: "
              "header, metadata and index, then level 0; `catpaq info`), against the mission's 64 KiB. The "
              "prefix grows with the number of nodes:")
            w("")
            w(md_table(["input", "nodes", "prefix bytes", "level 0 bytes", "first frame bytes", "within 64 KiB"],
                       [[r["input"], f"{r['nodes']:,}", f"{r['prefix']:,}", f"{r['level0']:,}", f"{r['total']:,}",
                         r["within"]] for r in first]))
            w("")
        if len(build) >= 2:
            plot_build(build, os.path.join(resdir, "build_speed.png"))
            w("![build speed](results/build_speed.png)")
            w("")
    else:
        w("```\n%s\n```" % read(os.path.join(raw, "build_bench.txt"))[-3000:])
        w("")

    w("### Memory budget (memory_budget_bench)")
    w("")
    w("`catpaq convert --memory B` is meant to bound the whole process. Each row converts the same "
      "generated mesh several times at one budget, from the smallest the tool accepts upwards, and "
      "takes each run's peak resident memory from the kernel (`wait4`), not from the tool's own report. "
      "*time ×1G* is the mean run time over that of the same input at 1 GiB in the same bench run. The "
      "uneven mesh (`make_uneven_density`) holds seven eighths of its triangles in a small sphere "
      "inside the blob: density varies about a hundredfold, so the largest leaves and diamonds, not the "
      "mean ones, set the memory.")
    w("")
    w(md_table(["input", "threads", "budget MiB", "runs", "peak MiB (min)", "peak MiB (max)", "max / budget",
                "time ×1G"],
               [[mb["input"].replace("generated ", ""), r["threads"], r["budget"], r["runs"], "%.1f" % r["lo"],
                 "%.1f" % r["hi"], "%.3f" % r["ratio"], "%.2f" % r["time"]]
                for mb in memory for r in mb["rows"]]))
    w("")

    # (3)
    w("## 3. Streaming over HTTP")
    w("")
    w("### 3.1 Bunny: orbit and zoom")
    w("")
    w("`catpaq serve` on the converted bunny (%s), `catpaq render http://127.0.0.1:PORT/api/datasets/bunny "
      "--no-converge --tolerance 1.5 --size 640x480` along two generated camera paths: an **orbit** (36 "
      "frames around the y axis) and a **zoom** to the tip of an ear (40 frames, geometric distance from "
      "2.5 to 0.02 bbox diagonals, then 12 frames holding the closest view). Each path is a fresh client "
      "(empty caches). With `--no-converge` each frame is one streaming step, so the frames show "
      "progressive refinement. Path setup: %s."
      % (read(os.path.join(raw, "serve.txt")).strip() or "?", paths_txt or "?"))
    w("")
    srows = []
    for name, rows in streams.items():
        if not rows:
            srows.append([name, "no statistics (render failed)", "", "", "", "", "", "", ""])
            continue
        last = rows[-1]
        srows.append([name, len(rows), fmt_bytes(last["bytes_fetched"]),
                      "%.1f%%" % (100 * last["bytes_fetched"] / size) if size else "?",
                      max(r.get("requests", 0) for r in rows), f"{max(r['triangles'] for r in rows):,}",
                      "%.3g" % last["certified_error_px"],
                      sum(1 for r in rows if r["certified_error_px"] <= r["tolerance_px"] and r["triangles"] > 0),
                      first_ok(rows, size)])
    w(md_table(["path", "frames", "bytes fetched", "of dataset", "requests", "max triangles",
                "certified error, last frame (px)", "frames within tolerance (drawn)",
                "first frame within tolerance: bytes so far"], srows))
    w("")
    w("Dataset size %s (%s bytes, %s nodes). Frames with nothing drawn yet are not counted as within "
      "tolerance. The bunny is small: a whole view of it at 640x480 and 1.5 px needs the finest level "
      "almost everywhere, so a path that sees all of it ends up fetching (nearly) the whole file; "
      "view-dependent savings need larger datasets than the one bundled."
      % (fmt_bytes(size), f"{size:,}", ver.get("diamonds", "?")))
    w("")
    if any(streams.values()):
        plot_stream(streams, size, os.path.join(resdir, "streaming.png"))
        w("![streaming](results/streaming.png)")
        w("")
        zr = (streams.get("zoom") or [])[-12:]
        if zr and min(r["certified_error_px"] for r in zr) > zr[0]["tolerance_px"]:
            w("In the last 12 frames of the zoom (holding the closest view, everything needed fetched) the "
              "certified error stays between %.3g and %.3g px: close to the ear the finest stored level "
              "cannot meet a %.1f px tolerance, whatever is fetched." %
              (min(r["certified_error_px"] for r in zr), max(r["certified_error_px"] for r in zr),
               zr[0]["tolerance_px"]))
            w("")
    for name in ("orbit", "zoom"):
        rows = streams.get(name) or []
        if not rows:
            continue
        n = len(rows)
        idx = sorted(set([0, 1, 2, n // 3, 2 * n // 3, n - 1]))
        titles = ["%s frame %d: %s tri, %s" % (name, i, f"{rows[i]['triangles']:,}",
                                               fmt_bytes(rows[i]["bytes_fetched"])) for i in idx]
        if frame_strip(os.path.join(work, "frames_" + name), idx,
                       os.path.join(resdir, "frames_%s.png" % name), titles):
            w("![%s frames](results/frames_%s.png)" % (name, name))
            w("")

    # (3b) streaming the scan-like dataset
    w("### 3.2 Scan-like mesh, %s triangles: orbit, zoom to a detail, fly-through" % f"{stream_tris:,}")
    w("")
    w("The same server also serves `make_scan_like(%s)` converted with defaults (%s, %s bytes). Three "
      "generated paths (y is the long axis, +z the front): an **orbit** (36 frames at 0.9 diagonals), "
      "a **zoom** to a detail on the front (40 frames from 2.5 to 0.1 diagonals, then 12 holding), and a "
      "**fly-through** (48 frames over the front from 5%% to 60%% of the height, 0.15 diagonals from the "
      "surface, looking 0.3 diagonals ahead). Path setup: %s. For each path:"
      % (f"{stream_tris:,}", fmt_bytes(scan_size), f"{scan_size:,}", scan_paths_txt or "?"))
    w("")
    w("- *progressive*: `catpaq render URL --no-converge --tolerance 1.5` from a cold start (fresh "
      "client), one streaming step per frame: triangles, bytes fetched so far, pending requests and "
      "certified error per frame, plus the **image error** of each frame against a reference;")
    w("- *reference*: the same path rendered from the local file at `--tolerance 0.1`, each frame "
      "converged (the finest stored level wherever it is visible); image error = PSNR over RGB and mean "
      "absolute difference (0-255 scale) of the progressive frame against it;")
    w("- *cold start*: the path's first view, and its last view, alone over HTTP (a fresh client each), "
      "rendered until it converges "
      "(`--tolerance 1.5`, no `--no-converge`): bytes and time to reach the tolerance from nothing "
      "(time from opening the dataset, prefix included; the wall time of the whole command also "
      "includes creating the EGL context and writing nothing else).")
    w("")
    crows = []
    for p in SCAN_PATHS:
        for view, k in (("first", 0), ("last", 1), ("last, fine", 1)):
            c = scan_cold[p, view]
            reached = c["certified_error_px"] <= c["tolerance_px"]
            crows.append(["%s, %s view%s" % (p, view.split(",")[0], " (leaf-triangles 500)" if "fine" in view else ""),
                          fmt_bytes(c["bytes_fetched"]) + ("" if reached else " (not reached)"),
                          "%.1f%%" % (100 * c["bytes_fetched"] / c["size"]), "%.1f%%" % (100 * in_frustum[p][k]),
                          c["requests"], f"{c['triangles']:,}", "%.0f" % c["elapsed_ms"], "%.0f" % c["wall_ms"],
                          "%.3g" % c["certified_error_px"]])
    w("**Cold start to tolerance (the first and the last view of each path alone, converged):**")
    w("")
    w(md_table(["view", "bytes to reach 1.5 px", "of dataset", "input vertices in the view frustum", "requests",
                "triangles drawn",
                "ms from opening the dataset", "ms wall (whole command)", "certified error (px)"], crows))
    w("")
    w("*(not reached)*: the view converged (nothing left to fetch) with a certified error above the "
      "tolerance: there the finest stored level is too coarse for 1.5 px. *(leaf-triangles 500)*: the same "
      "mesh converted with `--leaf-triangles 500` (%s, %s nodes, against %s and %s nodes with the default "
      "2000) and served next to it: finer nodes let the cut follow the view more closely."
      % (fmt_bytes(fine_size), fine_nodes, fmt_bytes(scan_size), scan_nodes))
    w("")
    frows = []
    for p in SCAN_PATHS:
        for view in ("first", "last"):
            c, n, wh, fb = scan_cold[p, view], scan_cold[p, view + ", no skip"], scan_cold[p, view + ", whole"], fetch_views[p, view]
            drawn = fb["total"]["cut"]["drawn"]
            frows.append(["%s, %s view" % (p, view), fmt_bytes(n["bytes_fetched"]), fmt_bytes(wh["bytes_fetched"]),
                          fmt_bytes(c["bytes_fetched"]),
                          fmt_bytes(drawn), "%.2f" % (wh["bytes_fetched"] / drawn), "**%.2f**" % (c["bytes_fetched"] / drawn),
                          "%.1f%%" % (100 * c["bytes_fetched"] / scan_size),
                          "%.1f%%" % (100 * fb["finest_vertices_in_frustum"]),
                          "%.2f" % ((c["bytes_fetched"] / scan_size) / max(1e-9, fb["finest_vertices_in_frustum"])),
                          "%.3g" % c["certified_error_px"]])
    w("**Fetched against drawn and against the view (cold start, converged, over HTTP):**")
    w("")
    w(md_table(["view", "fetched, every level, whole diamonds", "fetched, skipping levels, whole diamonds",
                "fetched, skipping levels, slots (default)", "drawn (the cut's fragments)",
                "fetched / drawn, whole diamonds", "fetched / drawn, slots", "fetched, of dataset",
                "finest level in the frustum", "fetched share / frustum share", "certified error (px)"], frows))
    w("")
    w("*Fetched*: the client's bytes to converge from a cold start, prefix included: with `--skip 0 "
      "--fetch-whole-nodes` (every level on the way is fetched, each drawn for a moment, diamonds whole), "
      "with skipping (`--skip 8`: a node within 8 times the tolerance that the view refines at once is "
      "not fetched) and whole diamonds (`--fetch-whole-nodes`, the client before slots were fetched "
      "alone), and with the defaults (skipping, and only the slots a refinement draws: a diamond's slot "
      "is drawn only while its creating parent is refined, so the slots its other, unrefined parents "
      "create are not fetched; the slot table gives each slot's byte range, and adjacent slots go in one "
      "range request). All converge to the same cut (the same triangles and image). *Drawn*: the "
      "compressed bytes of the fragments the converged cut shows (`bench/client/fetch_bench` on the "
      "same view). What remains above the drawn bytes: the prefix and the coarse preview levels.")
    w("")
    srows = []
    for p in SCAN_PATHS:
        rows = scan_streams[p]
        last = rows[-1]
        err = scan_imgerr[p]
        drawn = [e for e, r in zip(err, rows) if r["triangles"] > 0]
        within = [r for r in rows if r["certified_error_px"] <= r["tolerance_px"] and r["triangles"] > 0]
        first = within[0] if within else None
        srows.append([p, len(rows), fmt_bytes(last["bytes_fetched"]),
                      "**%.1f%%**" % (100 * last["bytes_fetched"] / scan_size),
                      "%.1f%%" % (100 * in_frustum[p][1]),
                      f"{max(r['triangles'] for r in rows):,}", max(r["pending"] for r in rows),
                      "%.3g" % last["certified_error_px"], len(within),
                      ("frame %d: %s, %.0f ms" % (first["frame"], fmt_bytes(first["bytes_fetched"]), first["elapsed_ms"]))
                      if first else "never",
                      "%.1f" % (sum(e["psnr"] for e in drawn) / len(drawn)) if drawn else "-",
                      "%.1f / %.2f" % (err[-1]["psnr"], err[-1]["mad"])])
    w("**Progressive streaming along the paths (cold start, one step per frame):**")
    w("")
    w(md_table(["path", "frames", "bytes fetched", "of dataset", "input vertices in the last frame's frustum",
                "max triangles", "max pending",
                "certified error, last frame (px)", "frames within tolerance", "first within tolerance",
                "mean PSNR (dB, drawn frames)", "last frame PSNR dB / MAD"], srows))
    w("")
    w("*Of dataset* is the fraction of the file the client fetched by the end of the path. *Input vertices "
      "in the frustum* (no occlusion) bounds what a perfectly view-dependent client would need for that "
      "view; a fetched fraction far above it means the cut refines well outside the view. PSNR of identical images is infinite and shown as 99 dB; the reference is rendered "
      "with the same renderer, so the remaining differences come from the cut (tolerance 1.5 px against "
      "0.1 px) and from frames not yet refined.")
    w("")
    plot_stream_scan(scan_streams, scan_imgerr, scan_size, os.path.join(resdir, "streaming_scan.png"))
    w("![streaming the scan-like dataset](results/streaming_scan.png)")
    w("")
    for p in SCAN_PATHS:
        rows = scan_streams[p]
        n = len(rows)
        idx = sorted(set([1, 3, n // 3, 2 * n // 3, n - 1]))
        titles = ["%s %d: %s tri, %s, %.1f dB" % (p, i, f"{rows[i]['triangles']:,}", fmt_bytes(rows[i]["bytes_fetched"]),
                                                 scan_imgerr[p][i]["psnr"]) for i in idx]
        if frame_strip(os.path.join(work, "frames_scan_" + p), idx, os.path.join(resdir, "frames_scan_%s.png" % p),
                       titles):
            w("![%s frames](results/frames_scan_%s.png)" % (p, p))
            w("")

    # (4)
    w("## 4. Render throughput: packed 8-byte vertices vs float (render_bench)")
    w("")
    if "packed" in rb and "float" in rb:
        w("%s. GL: %s. Finest cut: %s. Render %s." % (rb["dataset"], rb["gl"], rb["cut"], rb["render"].rstrip(":")))
        w("")
        w(md_table(["path", "best ms", "median ms", "Mtri/s (best)", "B/vertex", "B/vertex with indices",
                    "GPU MB"],
                   [[p, rb[p]["best"], rb[p]["median"], rb[p]["mtri"], rb[p]["bpv"], rb[p]["bpv_idx"],
                     rb[p]["gpu_mb"]] for p in ("packed", "float")]))
        w("")
        w("Ratio float/packed: %s. Images: %s. llvmpipe renders on the CPU, so frame times are CPU-bound "
          "and noisy (2 cores shared with the rest of the run); the memory figures are exact." %
          (rb["ratio"], rb["images"]))
    elif rb_rc == "124":
        w("Skipped: render_bench took longer than 60 s (short mode limit).")
    else:
        w("render_bench did not produce results (exit status %s):" % rb_rc)
        w("```\n%s\n```" % rb["text"][-2000:])
    w("")

    # hard cases
    w("## 5. Numerical stability: hard cases (bench/catp/hard_cases)")
    w("")
    w("Each generated hard case (`mesh/generators.h`) is converted, verified with `verify`'s checks and "
      "distance measures, and crack-checked as in the tests: cuts decoded exactly as the vertex shader "
      "does, welded by exact position, border edges counted (%s). A case **passes** when the converter "
      "accepts it, no invariant is broken, no cut has a border edge away from the original border (a "
      "crack), and every level's measured distance to the original is within its stored bound; or it "
      "is **refused** with a message. *Border edges found* counts all border edges of the worst cut "
      "(for open inputs these lie on the original border; clipping splits border edges, so the count "
      "can exceed the input's); *off the border* must be 0."
      % hard["settings"].replace("converter: ", "converter "))
    w("")
    w(md_table(["case", "triangles", "input border edges", "outcome", "cuts checked",
                "border edges found (max)", "off the original border", "max error / diagonal",
                "max error / stored bound", "detail"],
               [[c["name"], f"{c['triangles']:,}", c["border_in"], "**%s**" % c["outcome"], c["cuts"],
                 c["border_found"], c["off_border"], "%.3g" % c["err_rel"], "%.2f" % c["err_over_bound"],
                 c["detail"] or ""] for c in hard["cases"]]))
    w("")
    npass = sum(c["outcome"] == "passes" for c in hard["cases"])
    nref = sum(c["outcome"] == "refused" for c in hard["cases"])
    w("%d of %d cases pass, %d refused with a message, %d fail." %
      (npass, len(hard["cases"]), nref, len(hard["cases"]) - npass - nref))
    w("")

    try:
        report_formats.aqp_section(raw, ver["levels"], size, conv_s, int(info.get("vertices", "0") or 0), w)
        report_formats.points_section(raw, w)
        report_formats.stream_section(raw, SCAN_PATHS, stream_tris, w)
    except report_formats.ReportError as e:
        require(False, str(e))

    w("## Not covered yet")
    w("")
    w("- The larger meshes are generated (`make_scan_like`), not real scans: no real scanned model "
      "beyond the bunny is bundled.")
    w("- Streaming runs on localhost without a bandwidth or latency model: bytes and requests are exact, "
      "times are those of this machine's loopback, with llvmpipe rendering on the same 2 cores.")
    w("- Image error compares against a reference made by the same renderer (tolerance 0.1 px), not "
      "against a rendering of the original mesh.")
    zl, zw = scan_cold["zoom", "last"], scan_cold["zoom", "last, whole"]
    fz = fetch_views["zoom", "last"]
    w("- Fetching is per slot (the parts a refinement draws, section 3): the zoom's last view alone, from a "
      "cold start, fetches %.0f%% of the dataset (%.0f%% fetching whole diamonds) while %.0f%% of the "
      "input's vertices lie in its view frustum: %.2f times the bytes it draws (%.2f whole). What remains "
      "above the drawn bytes is the coarser levels a refinement passes through and the slots of drawn "
      "diamonds that are not in the view." %
      (100 * zl["bytes_fetched"] / zl["size"], 100 * zw["bytes_fetched"] / zw["size"], 100 * in_frustum["zoom"][1],
       zl["bytes_fetched"] / fz["total"]["cut"]["drawn"], zw["bytes_fetched"] / fz["total"]["cut"]["drawn"]))
    w("- AQP and points are streamed along the same views as CATP (section 8). The points' bytes are set "
      "beside LAZ's at the same quantization (section 7), written by our own LAZ writer and checked point "
      "for point by laz-perf, not by LASzip or laspy with lazrs (no PyPI here); LAZ has no hierarchy, so "
      "that is a comparison of bytes at the finest level only. The point datasets are not compared with "
      "Potree-style octrees.")
    w("- CATP leaves follow the density (a tetrahedron splits while it holds more than 6 times the "
      "target), but the out-of-core blocks are all of one size, set by the densest part: where a small "
      "budget or a dense part asks for blocks finer than a sparse part's leaves, those leaves gather "
      "their triangles across blocks through a scratch file (the 10M `make_uneven_density` mesh at "
      "1 GiB: 8,433 such leaves, 390 MiB of scratch data; measured with `catpaq convert`). Blocks that "
      "follow the density too would avoid it.")
    w("- The hard-case suite runs each case at one leaf level (7) and one seed; the crack tests "
      "(`tests/catp/test_cracks.cpp`) and error tests cover the same cases in ctest.")
    if mode == "short":
        w("- Short mode: 300k-triangle scan for both rate-distortion and streaming, build bench at 100k only, "
          "no codec_bench on the scan.")
    w("")

    with open(os.path.join(docs, "RESULTS.md"), "w") as f:
        f.write("\n".join(L))
    print("wrote", os.path.join(docs, "RESULTS.md"))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("paths")
    p.add_argument("--mesh", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--kind", choices=["bunny", "scan"], default="bunny")
    p = sub.add_parser("compare")
    p.add_argument("--ref", required=True)
    p.add_argument("--frames", required=True)
    p.add_argument("--out", required=True)
    p = sub.add_parser("write")
    p.add_argument("--raw", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--docs", required=True)
    a = ap.parse_args()
    try:
        if a.cmd == "paths":
            make_paths(a.mesh, a.out, a.kind)
        elif a.cmd == "compare":
            compare_frames(a.ref, a.frames, a.out)
        else:
            write_report(a.raw, a.work, a.docs)
    except ReportError as e:
        sys.exit("report.py: " + str(e))


if __name__ == "__main__":
    main()
