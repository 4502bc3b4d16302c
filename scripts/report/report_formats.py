"""Sections 6 (AQP beside CATP) and 7 (points) of docs/RESULTS.md, from the raw outputs of
aqp_bench, `catpaq convert --format aqp --json`, `catpaq verify` on AQP datasets and points_bench
(scripts/report/run.sh). report.py calls aqp_section and points_section."""
import json
import os
import re

NUM = r"[-+0-9.eE]+"


class ReportError(Exception):
    pass


def need(cond, what):
    if not cond:
        raise ReportError(what)


def read(path):
    with open(path) as f:
        return f.read()


def md_table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def parse_aqp_bench(text):
    """aqp_bench output -> list of models with build, size, levels and the CATP reference."""
    models = []
    for block in re.split(r"^(?=model )", text, flags=re.M):
        m = re.match(r"model (\S+): (\d+) triangles, (\d+) vertices", block)
        if not m:
            continue
        d = {"name": m.group(1), "triangles": int(m.group(2)), "vertices": int(m.group(3))}
        b = re.search(r"build (%s) s wall, (%s) s cpu .*?, (%s) input triangles/s, peak (%s) MiB" % (NUM, NUM, NUM, NUM), block)
        need(b, "aqp_bench: no build line for %s" % d["name"])
        d.update(wall=float(b.group(1)), cpu=float(b.group(2)), rate=float(b.group(3)), peak=float(b.group(4)))
        s = re.search(r"size: (\d+) bytes file, (\d+) payload, (%s) bits/sample" % NUM, block)
        need(s, "aqp_bench: no size line for %s" % d["name"])
        d.update(file_bytes=int(s.group(1)), payload=int(s.group(2)), bits_per_sample=float(s.group(3)))
        p = re.search(r"domain: (\d+) base triangles, (\d+) patches of (\d+)x\d+ samples, (\d+) samples", block)
        need(p, "aqp_bench: no domain line for %s" % d["name"])
        d.update(base=int(p.group(1)), patches=int(p.group(2)), side=int(p.group(3)), samples=int(p.group(4)))
        a = re.search(r"distortion: angle mean (%s) p99 (%s) max (%s); area mean (%s) p99 (%s)" % ((NUM,) * 5), block)
        need(a, "aqp_bench: no distortion line for %s" % d["name"])
        d.update(angle_mean=float(a.group(1)), angle_p99=float(a.group(2)), area_mean=float(a.group(4)),
                 area_p99=float(a.group(5)))
        d["levels"] = [{"level": int(r[0]), "samples": int(r[1]), "bytes": int(r[2]), "bits": float(r[3]),
                        "max_rel": float(r[4]), "mean_rel": float(r[5])}
                       for r in re.findall(r"^\s+(\d+)\s+(\d+)\s+(\d+)\s+(%s)\s+(%s)\s+(%s)$" % (NUM, NUM, NUM), block, re.M)]
        need(d["levels"], "aqp_bench: no level rows for %s" % d["name"])
        c = re.search(r"reference, CATP on the same mesh: (%s) s wall, (%s) s cpu, (\d+) bytes, (\d+) levels, "
                      r"bounds/diag finest (%s) coarsest (%s)" % (NUM, NUM, NUM, NUM), block)
        need(c, "aqp_bench: no CATP reference for %s" % d["name"])
        d["catp"] = {"wall": float(c.group(1)), "cpu": float(c.group(2)), "bytes": int(c.group(3)),
                     "levels": int(c.group(4)), "finest_rel": float(c.group(5)), "coarsest_rel": float(c.group(6))}
        models.append(d)
    need(models, "aqp_bench.txt: no models parsed")
    return models


def parse_aqp_verify(text):
    """verify on an AQP dataset -> per-level measured distances (relative to the diagonal)."""
    need("verify: OK" in text, "AQP verify did not pass:\n" + text[-2000:])
    rows = []
    for r in re.findall(r"^\s*(\d+)\s+(\d+)\s+(%s)\s+(%s) \((%s)\)\s+(%s) \((%s)\)" % ((NUM,) * 5), text, re.M):
        rows.append({"level": int(r[0]), "triangles": int(r[1]), "bound": float(r[2]), "l2o": float(r[3]),
                     "l2o_rel": float(r[4]), "o2l": float(r[5]), "o2l_rel": float(r[6])})
    need(rows, "AQP verify: no level rows")
    return rows


def parse_points_bench(text):
    out = {"conversion": [], "splits": [], "rate": []}
    for r in re.findall(r"^\s+(\d+)\s+(%s)\s+(%s)\s+(%s)\s+(\d+)\s+(%s)\s+(\d+)\s+(%s)\s+(%s)\s+(%s)\s+(%s)\s+(\S+)$"
                        % ((NUM,) * 8), text, re.M):
        out["conversion"].append({"points": int(r[0]), "wall": float(r[1]), "cpu": float(r[2]), "mpts": float(r[3]),
                                  "peak": int(r[4]), "bpt": float(r[5]), "nodes": int(r[6]),
                                  "b_stored": float(r[7]), "err_r": float(r[8]), "meshopt_mpts": float(r[9]),
                                  "ratio": float(r[10]), "split": r[11]})
    need(out["conversion"], "points_bench: no conversion rows")
    firsts = re.findall(r"^\s+first frame: (\d+) bytes \(prefix (\d+), level 0 (\d+)\)$", text, re.M)
    need(len(firsts) == len(out["conversion"]), "points_bench: one first-frame line per conversion expected")
    for c, f in zip(out["conversion"], firsts):
        c["first_frame"], c["prefix"], c["level0"] = int(f[0]), int(f[1]), int(f[2])
    d = re.search(r"^ours:\s+(%s) M points/s\s+(%s) B/point" % (NUM, NUM), text, re.M)
    mo = re.search(r"^meshopt:\s+(%s) M points/s\s+(%s) B/point" % (NUM, NUM), text, re.M)
    need(d and mo, "points_bench: no decode lines")
    out["decode"] = {"ours": float(d.group(1)), "ours_b": float(d.group(2)), "meshopt": float(mo.group(1)),
                     "meshopt_b": float(mo.group(2))}
    for r in re.findall(r"^(scan|uneven)\s+(midpoint|balanced)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(%s)\s+(%s)$"
                        % (NUM, NUM), text, re.M):
        out["splits"].append(list(r))
    for r in re.findall(r"^ (\d/\d)\s+(%s)\s+(%s)\s+(%s)\s+(%s)$" % ((NUM,) * 4), text, re.M):
        out["rate"].append(list(r))
    ooc = re.search(r"^== out of core \(the largest cloud; the in-core conversion above: (%s) s, peak (%s) MiB\)$"
                    % (NUM, NUM), text, re.M)
    out["out_of_core"] = []
    if ooc:
        out["out_of_core_in_core"] = {"wall": float(ooc.group(1)), "peak": float(ooc.group(2))}
        for r in re.findall(r"^\s+(\d+)\s+(%s)\s+(%s)\s+(%s)\s+(\d+)\s+(%s)\s+(\d+)\s+(\d+)\s+(%s)\s+(yes|NO)$"
                            % ((NUM,) * 5), text, re.M):
            out["out_of_core"].append({"budget": int(r[0]), "wall": float(r[1]), "cpu": float(r[2]),
                                       "mpts": float(r[3]), "peak": int(r[4]), "peak_budget": float(r[5]),
                                       "chunks": int(r[6]), "passes": int(r[7]), "ratio": float(r[8]),
                                       "same": r[9] == "yes"})
        need(out["out_of_core"], "points_bench: an out-of-core heading without rows")
    out["laz"] = parse_points_bench_laz(text)
    out["normals"] = None
    nq = re.search(r"^== estimated normals against the surface's \((\d+) points, (\d+) leaf points matched\)\n.*\n"
                   r"\s*(%s)\s+(%s)\s+(%s)\s+(%s)\s+(%s)$" % ((NUM,) * 5), text, re.M)
    if nq:
        out["normals"] = {"points": int(nq.group(1)), "matched": int(nq.group(2)), "mean": float(nq.group(3)),
                          "median": float(nq.group(4)), "p95": float(nq.group(5)), "flipped": float(nq.group(6))}
    return out


def parse_points_bench_laz(text):
    """points_bench --laz: the LAZ rows, the leaves' grid steps and our bytes beside them (None
    without the part)."""
    head = re.search(r"^== LAZ at our quantization \((\d+) points", text, re.M)
    if not head:
        return None
    steps = re.search(r"^leaf grid step: median (%s), smallest (%s), largest (%s) \((\d+) leaves, (\d+) points\)$"
                      % (NUM, NUM, NUM), text, re.M)
    leaves = re.search(r"^ours, leaves: (%s) B/point" % NUM, text, re.M)
    levels = re.search(r"^ours, all levels: (%s) B/stored point, (%s) B/input point; position\+colour (%s) B/stored "
                       r"point, (%s) B/input point$" % ((NUM,) * 4), text, re.M)
    split = re.search(r"^ours, payload split \(all levels\): position (%s)%%, normal (%s)%%, colour (%s)%%, radius "
                      r"(%s)%%, header (%s)%%$" % ((NUM,) * 5), text, re.M)
    leaf_pc = re.search(r"^ours, leaves, position\+colour: about (%s) B/point" % NUM, text, re.M)
    need(steps and leaves and levels and split and leaf_pc, "points_bench: an incomplete LAZ part")
    rows = []
    for r in re.findall(r"^(median leaf|smallest leaf)\s+(input|Morton)\s+(%s)\s+(%s)\s+(%s)\s+(%s)\s+(.+)$"
                        % ((NUM,) * 4), text, re.M):
        rows.append({"step": r[0], "order": r[1], "scale": float(r[2]), "bpt": float(r[3]), "data_bpt": float(r[4]),
                     "seconds": float(r[5]), "check": r[6].strip()})
    need(rows, "points_bench: a LAZ heading without rows")
    for r in rows:
        need(r["check"] == "identical" or r["check"].startswith("not checked"),
             "points_bench: laz-perf check '%s'" % r["check"])
    return {"points": int(head.group(1)), "median_step": float(steps.group(1)), "smallest_step": float(steps.group(2)),
            "largest_step": float(steps.group(3)), "leaves": int(steps.group(4)), "leaf_points": int(steps.group(5)),
            "leaf_bpt": float(leaves.group(1)), "stored_bpt": float(levels.group(1)), "input_bpt": float(levels.group(2)),
            "pc_stored_bpt": float(levels.group(3)), "pc_input_bpt": float(levels.group(4)),
            "split": [float(split.group(i)) for i in range(1, 6)], "leaf_pc_bpt": float(leaf_pc.group(1)), "rows": rows}


def aqp_section(raw, catp_verify_levels, catp_bunny_bytes, catp_convert_s, bunny_vertices, w):
    """Section 6. `catp_verify_levels`: report.py's parse_verify rows of the CATP bunny."""
    models = parse_aqp_bench(read(os.path.join(raw, "aqp_bench.txt")))
    w("## 6. AQP beside CATP (aqp_bench, convert --format aqp, verify)")
    w("")
    w("The bunny converted both ways and measured by `verify --mesh` against the original (largest "
      "two-sided distance of the finest level over surface samples, relative to the bounding-box "
      "diagonal): CATP keeps the input's triangles at its finest level, AQP resamples the surface on "
      "regular grids over its patches, so at a given size its error is that of the sampling. "
      "Bits are per input vertex over all levels (the whole file).")
    w("")
    rows = []
    fin = catp_verify_levels[-1]
    rows.append(["CATP (default)", "%d levels" % len(catp_verify_levels), f"{catp_bunny_bytes:,}",
                 "%.1f" % (8 * catp_bunny_bytes / bunny_vertices), "%.2g" % max(fin["l2o_rel"], fin["o2l_rel"]),
                 catp_convert_s])
    for level in ("default", "5"):
        rep = json.loads(read(os.path.join(raw, "aqp_bunny_%s.json" % level)).strip().splitlines()[-1])
        ver = parse_aqp_verify(read(os.path.join(raw, "aqp_verify_bunny_%s.txt" % level)))
        f = ver[-1]
        side = (1 << rep["patch_level"]) + 1
        rows.append(["AQP (%s)" % ("default" if level == "default" else "--patch-level " + level),
                     "%d patches of %dx%d, %s samples" % (rep["patches"], side, side, f"{rep['samples']:,}"),
                     f"{rep['output']['bytes']:,}", "%.1f" % (8 * rep["output"]["bytes"] / bunny_vertices),
                     "%.2g" % max(f["l2o_rel"], f["o2l_rel"]), "%.2f" % rep["seconds"]])
    w(md_table(["bunny", "layout", "bytes", "bits / input vertex", "finest level, max distance / diagonal",
                "convert s"], rows))
    w("")
    w("The converters on the same meshes in one process (`aqp_bench`; CATP as its reference): build "
      "time, bytes, and the stored bounds of the finest level (AQP's are exact bounds of the parametric "
      "distance, CATP's of the quantization and simplification), with AQP's bits per finest sample and "
      "the parameterization's distortion (angle: singular value ratio; area-weighted mean and 99th "
      "percentile).")
    w("")
    w(md_table(["mesh", "AQP build s", "CATP build s", "AQP / CATP time", "AQP bytes", "CATP bytes",
                "AQP finest bound / diag", "CATP finest bound / diag", "AQP bits / finest sample (all levels)",
                "AQP finest level alone", "angle distortion mean / p99"],
               [[m["name"] + " (%s tri)" % f"{m['triangles']:,}", "%.2f" % m["wall"], "%.2f" % m["catp"]["wall"],
                 "%.1f" % (m["wall"] / max(m["catp"]["wall"], 1e-9)), f"{m['file_bytes']:,}",
                 f"{m['catp']['bytes']:,}", "%.2g" % m["levels"][-1]["max_rel"], "%.2g" % m["catp"]["finest_rel"],
                 "%.1f" % m["bits_per_sample"], "%.1f" % m["levels"][-1]["bits"],
                 "%.2f / %.2f" % (m["angle_mean"], m["angle_p99"])] for m in models]))
    w("")
    ooc_section(raw, w)
    render_rows(parse_aqp_render_bench(read(os.path.join(raw, "aqp_render_bench.txt"))), w)
    big = models[-1]
    w("Per level on %s: bits per sample %s (coarse to fine): every node is one PNG of byte planes "
      "(docs/formats/aqp.md) holding a *tile* of neighbouring patches, as many as keep it within 512 stored "
      "samples (levels 0-3: 64, 64, 16 and 4 patches; finer levels one), so a coarse level pays a PNG's "
      "fixed overhead (signature, header chunk, zlib stream: about 60 bytes), deflate's code tables and an "
      "index entry once per tile instead of once per patch of a few samples; levels 0-1 still cost more per "
      "sample than the finest. The paper's 24 bits per sample is %s here over all levels (%.1f at the "
      "finest level alone). Before tiles (one patch per node) `bench/aqp/node_bench` measured 22.7 bits "
      "per sample over all levels on a 1M-triangle scan-like mesh, and level 0 of its 900 patches 101 KB as "
      "900 images against 27 KB as one; section 8 streams the same mesh with and without tiles." %
      (big["name"], ", ".join("%.0f" % l["bits"] for l in big["levels"]),
       "met" if big["bits_per_sample"] <= 24 else "not met", big["levels"][-1]["bits"]))
    w("")


def ooc_section(raw, w):
    """A mesh above the in-core budget: the out-of-core reduction, the conversion and verify."""
    rep = json.loads(read(os.path.join(raw, "aqp_ooc.json")).strip().splitlines()[-1])
    ms, budget = read(os.path.join(raw, "aqp_ooc_ms.txt")).split()
    ver = parse_aqp_verify(read(os.path.join(raw, "aqp_ooc_verify.txt")))
    red = rep["reduction"]
    need(red is not None, "aqp_ooc.json: the mesh was not reduced (it fit the budget)")
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    budget_bytes = int(budget[:-1]) * units[budget[-1]]
    diag = rep["diagonal"]
    f = ver[-1]
    w("A mesh above the budget (`convert --format aqp --memory %s` of a gen_mesh scan, `aqp/reduce.h`): the "
      "PLY is simplified out of core, block by block from scratch files, to the most triangles whose "
      "conversion fits, then converted; the largest distance of an input vertex to the reduced mesh is "
      "added to every node's error, and `verify --mesh` measures the result against the original file." % budget)
    w("")
    w(md_table(["input triangles", "--memory", "reduced to", "blocks", "reduction s", "whole conversion s",
                "peak MiB", "input vertex distance / diag", "finest bound / diag", "verify: finest max / diag"],
               [[f"{red['input_triangles']:,}", budget, f"{red['triangles']:,}", str(red["blocks"]),
                 "%.1f" % red["seconds"], "%.1f" % (int(ms) / 1000.0),
                 "%d (%.0f%% of the budget)" % (rep["peak_rss"] >> 20, 100.0 * rep["peak_rss"] / budget_bytes),
                 "%.2g" % (red["vertex_distance"] / diag), "%.2g" % (rep["levels"][-1]["max_error"] / diag),
                 "%.2g" % max(f["l2o_rel"], f["o2l_rel"])]]))
    w("")


def parse_aqp_render_bench(text):
    m = re.search(r"^mesh: (\d+) triangles; AQP: (\d+) patches, finest level (\d+)", text, re.M)
    d = re.search(r"^AQP decode \(one thread.*?\): (%s) MB in (%s) s = (%s) MB/s compressed, (%s) M samples/s, (%s) "
                  r"compressed bytes per sample" % ((NUM,) * 5), text, re.M)
    t = re.search(r"^(\d+)x(\d+), tolerance (%s) px, median of (\d+) frames" % NUM, text, re.M)
    need(m and d and t, "aqp_render_bench: header, decode or settings line missing")
    rows = re.findall(r"^\s+(\d+) (AQP|CATP)\s+(\d+)\s+(\d+)\s+(%s)\s+(%s)\s+(%s)\s+(%s)\s+(%s)\s+(%s)$"
                      % ((NUM,) * 6), text, re.M)
    need(rows, "aqp_render_bench: no view rows")
    return {"triangles": int(m.group(1)), "patches": int(m.group(2)), "level": int(m.group(3)),
            "decode_mbs": float(d.group(3)), "decode_msps": float(d.group(4)), "bytes_per_sample": float(d.group(5)),
            "size": "%sx%s" % (t.group(1), t.group(2)), "tolerance": float(t.group(3)), "frames": int(t.group(4)),
            "rows": rows}


def render_rows(ab, w):
    w("AQP's client against CATP's on a %s-triangle scan-like mesh (AQP: %d patches, finest level %d), in one "
      "GL context (`bench/client/aqp_render_bench`; llvmpipe, so frame times include rasterization on the "
      "CPU): decoding the level chains of every patch on one thread ran at **%.1f MB/s of PNG, %.1f M samples/s** "
      "(%.2f compressed bytes per sample; section 1 has CATP's decode). Sessions converged to %.2f px on "
      "the same views at %s, median of %d frames:" %
      (f"{ab['triangles']:,}", ab["patches"], ab["level"], ab["decode_mbs"], ab["decode_msps"], ab["bytes_per_sample"],
       ab["tolerance"], ab["size"], ab["frames"]))
    w("")
    w(md_table(["view", "format", "nodes drawn", "triangles", "GPU MB", "fetched MB", "certified px", "frame ms",
                "submit ms"], [[r[0], r[1], r[2], f"{int(r[3]):,}", r[4], r[5], r[6], r[7], r[8]] for r in ab["rows"]]))
    w("")


def points_section(raw, w):
    """Section 7."""
    pb = parse_points_bench(read(os.path.join(raw, "points_bench.txt")))
    w("## 7. Points (points_bench)")
    w("")
    w("Random samples of the scan-like surface with colours; normals and radii estimated by the "
      "converter. Each conversion runs in a child process reading a binary PLY, so its peak memory is "
      "its own (reading included). Baseline in the same run: meshoptimizer's `meshopt_simplifyPoints` "
      "halving the same cloud (one pass, one thread); *ratio* is our input points/s over its.")
    w("")
    w(md_table(["input points", "wall s", "CPU s", "M points/s", "peak MiB", "bytes / input point", "nodes",
                "bytes / stored point", "error / radius", "meshopt M points/s", "ratio"],
               [[f"{c['points']:,}", "%.2f" % c["wall"], "%.2f" % c["cpu"], "%.3f" % c["mpts"], c["peak"],
                 "%.2f" % c["bpt"], c["nodes"], "%.2f" % c["b_stored"], "%.3f" % c["err_r"],
                 "%.2f" % c["meshopt_mpts"], "%.2f" % c["ratio"]] for c in pb["conversion"]]))
    w("")
    w("The first frame of each dataset (what a client fetches before it draws the whole cloud: header, "
      "metadata and index, then level 0; `archive_first_frame`), against the mission's 64 KiB. The "
      "prefix grows with the number of nodes (the index and the metadata's node table hold every node):")
    w("")
    w(md_table(["input points", "nodes", "prefix bytes", "prefix bytes / node", "level 0 bytes", "first frame bytes",
                "within 64 KiB"],
               [[f"{c['points']:,}", c["nodes"], f"{c['prefix']:,}", "%.1f" % (c["prefix"] / max(1, c["nodes"])),
                 f"{c['level0']:,}", f"{c['first_frame']:,}", "yes" if c["first_frame"] <= 65536 else "**no**"]
                for c in pb["conversion"]]))
    w("")
    d = pb["decode"]
    w("Decoding every node of the first dataset on one thread: **%.1f M points/s** at %.2f bytes per "
      "point; meshoptimizer's vertex codec on the same decoded points (24-byte vertices) %.1f M points/s "
      "at %.2f bytes: ours is %.2f times its speed at %.2f times its size." %
      (d["ours"], d["ours_b"], d["meshopt"], d["meshopt_b"], d["ours"] / d["meshopt"], d["ours_b"] / d["meshopt_b"]))
    w("")
    if pb["normals"]:
        n = pb["normals"]
        w("Estimated normals against the surface's own (the first size's cloud converted again without its "
          "normals; each of the %s leaf points matched to its input point): angle between the two lines mean "
          "%.2f°, median %.2f°, 95th percentile %.2f°; %.3f%% point the other way (the orientation's failures: the "
          "surface is closed and its normals point out)." % (f"{n['matched']:,}", n["mean"], n["median"], n["p95"],
                                                             n["flipped"]))
        w("")
    if pb["laz"]:
        laz_table(pb["laz"], w)
    if pb["splits"]:
        w("Split rules (seed 002's midpoint against seed 000's balanced split):")
        w("")
        w(md_table(["cloud", "split", "nodes", "depth", "smallest leaf", "mean leaf", "bytes / point", "CPU s"],
                   pb["splits"]))
        w("")
    if pb["rate"]:
        w("Bytes per point against the colour precision (luma/chroma bits) and the position error "
          "allowed (a fraction of the node's smallest splat radius):")
        w("")
        w(md_table(["colour bits", "error / radius allowed", "bytes / input point", "bytes / stored point",
                    "error / radius measured"], pb["rate"]))
        w("")
    slowest = min(c["mpts"] for c in pb["conversion"])
    largest = max(pb["conversion"], key=lambda c: c["points"])
    w("In core, the largest cloud (%s points) peaked at %s MiB, %.0f bytes per input point." %
      (f"{largest['points']:,}", largest["peak"], float(largest["peak"]) * 1048576 / largest["points"]))
    w("")
    if pb["out_of_core"]:
        ic = pb["out_of_core_in_core"]
        w("Out of core (`convert --memory` below the in-core estimate): the largest cloud again in a child "
          "process under each budget, peak resident memory from the kernel; *time ratio* is the wall time "
          "over the in-core conversion's above (%.1f s, peak %.0f MiB) in the same run; *same* says whether "
          "the dataset is byte-identical to the in-core one (it must be)." % (ic["wall"], ic["peak"]))
        w("")
        w(md_table(["budget MiB", "wall s", "CPU s", "M points/s", "peak MiB", "peak / budget", "chunks",
                    "split passes", "time ratio", "same dataset"],
                   [[r["budget"], "%.1f" % r["wall"], "%.1f" % r["cpu"], "%.3f" % r["mpts"], r["peak"],
                     "%.3f" % r["peak_budget"], r["chunks"], r["passes"], "%.2f" % r["ratio"],
                     "yes" if r["same"] else "**NO**"] for r in pb["out_of_core"]]))
        w("")
    w("Targets (issue 18): conversion at least 1M points/s on 2 cores at every size: %s (slowest %.2f M points/s); "
      "at most 3.6 bytes per stored point at a quarter radius error: %s (%.2f with lossless colour); "
      "decoding at least 100 M points/s per core: %s (%.0f in this run)." %
      ("met" if slowest >= 1 else "not met", slowest,
       "met" if min(c["b_stored"] for c in pb["conversion"]) <= 3.6 else "not met with lossless colour",
       min(c["b_stored"] for c in pb["conversion"]), "met" if d["ours"] >= 100 else "not met", d["ours"]))
    w("")
    w("The conversion rate depends on the host as well as on the code; the same-run baseline says how fast "
      "this host was: meshoptimizer's `meshopt_simplifyPoints` ran at %.1f-%.1f M points/s here, and our rate "
      "over its was %.2f-%.2f." %
      (min(c["meshopt_mpts"] for c in pb["conversion"]), max(c["meshopt_mpts"] for c in pb["conversion"]),
       min(c["ratio"] for c in pb["conversion"]), max(c["ratio"] for c in pb["conversion"])))
    w("")


def laz_table(z, w):
    """Section 7's LAZ comparison (points_bench --laz)."""
    w("LAZ at the same quantization, same run: the first cloud (%s points) written as LAZ by our own "
      "writer (`bench/points/laz_writer.cpp`: LASzip's pointwise-chunked format, POINT10 v2 and RGB12 v2 "
      "items, chunks of 50,000 points, point format 2), with the scale set to the grid step our converter "
      "used at the leaves (the median over the %d leaves, %.3g, and the smallest, %.3g; the largest is "
      "%.3g), offsets at the cloud's minimum and colours as 16-bit v * 257. Each file is decoded by "
      "laz-perf (npm laz-perf 0.0.7, hobuinc's LASzip decoder in WebAssembly, "
      "`scripts/report/laz_decode.mjs`) and compared with the records written: *identical* means every "
      "point, bit for bit. LASzip itself (laspy with lazrs) cannot be installed here (no PyPI): our "
      "writer stands in for it and laz-perf checks it. LAZ predicts each point from the one before it in "
      "the file, so its size depends on the order: *input* is the samples' random order, *Morton* the "
      "same points sorted along a Morton curve of their integers first (a coherent order, as a "
      "scanner's acquisition order is; our converter sorts each node along a Morton curve too). "
      "Encoding time is one thread's wall time in memory." %
      (f"{z['points']:,}", z["leaves"], z["median_step"], z["smallest_step"], z["largest_step"]))
    w("")
    w(md_table(["LAZ scale", "point order", "scale", "LAZ bytes / point", "encode s", "laz-perf"],
               [[r["step"] + " step", r["order"], "%.4g" % r["scale"], "%.3f" % r["bpt"], "%.3f" % r["seconds"],
                 r["check"]] for r in z["rows"]]))
    w("")
    morton = [r for r in z["rows"] if r["step"] == "median leaf" and r["order"] == "Morton"]
    s = z["split"]
    w("Ours on the same cloud: the leaves (which hold the %s input points, quantized at the steps above) "
      "take %.3f bytes per point, and they also carry normals and radii (the payload split over all "
      "levels: position %.0f%%, normal %.0f%%, colour %.0f%%, radius %.0f%%, node headers %.1f%%); the "
      "position and colour part, that split applied to the leaves, is about %.3f bytes per point%s. The "
      "whole dataset (every level: the file a client streams) takes %.3f bytes per stored point and "
      "%.3f per input point, of which position and colour %.3f and %.3f." %
      (f"{z['leaf_points']:,}", z["leaf_bpt"], s[0], s[1], s[2], s[3], s[4], z["leaf_pc_bpt"],
       (", %.2f times LAZ's in Morton order at the median step (%.3f)" % (z["leaf_pc_bpt"] / morton[0]["bpt"],
                                                                          morton[0]["bpt"]) if morton else ""),
       z["stored_bpt"], z["input_bpt"], z["pc_stored_bpt"], z["pc_input_bpt"]))
    w("")


def read_jsonl_one(path):
    rows = [json.loads(l) for l in read(path).splitlines() if l.strip()]
    need(len(rows) == 1, "%s: expected one frame" % path)
    return rows[0]


def stream_section(raw, paths, stream_triangles, w):
    """Section 8: the streaming mesh as CATP, AQP and points, cold starts on the same views."""
    catp_size = int(read(os.path.join(raw, "scan_dataset_size.txt")).strip())
    aqp = json.loads(read(os.path.join(raw, "convert_scan_aqp.json")).strip().splitlines()[-1])
    pts = json.loads(read(os.path.join(raw, "convert_scan_points.json")).strip().splitlines()[-1])
    aqp1 = json.loads(read(os.path.join(raw, "convert_scan_aqp1.json")).strip().splitlines()[-1])
    sizes = {"scan": catp_size, "scanaqp": aqp["output"]["bytes"], "scanaqp1": aqp1["output"]["bytes"],
             "scanpts": pts["output"]["bytes"]}
    names = {"scan": "CATP", "scanaqp": "AQP", "scanaqp1": "AQP, a patch per node", "scanpts": "points"}
    aqp_s = float(read(os.path.join(raw, "convert_scan_aqp_ms.txt")).strip()) / 1000
    pts_s = float(read(os.path.join(raw, "convert_scan_points_ms.txt")).strip()) / 1000
    w("## 8. The three formats on the same views (cold starts over HTTP)")
    w("")
    w("The streaming mesh of section 3 (%s triangles) converted three ways with default settings: CATP "
      "(%s bytes), AQP (%s bytes, %d patches of %dx%d samples, converted in %.1f s) and its %s vertices as "
      "a point cloud (%s bytes, normals and radii estimated, converted in %.1f s). A fresh client renders "
      "each view alone from our server until it converges at 1.5 px (`render --tolerance 1.5`), as in "
      "section 3.2: the bytes and requests it took, what it drew and the command's wall time. The three "
      "errors are not the same quantity: CATP's and AQP's bound the distance to the original surface, "
      "the points' the distance from an input point to its splat, so equal tolerances are not equal "
      "image quality. *AQP, a patch per node*: the same AQP conversion with `--tile-samples 0` "
      "(%s bytes, %s nodes against %s), the layout before tiles: every level of every patch a node of "
      "its own, where AQP's default groups each level's neighbouring patches into tiles of at most 512 "
      "stored samples (docs/formats/aqp.md)." %
      (f"{stream_triangles:,}", f"{catp_size:,}", f"{sizes['scanaqp']:,}", aqp["patches"],
       (1 << aqp["patch_level"]) + 1, (1 << aqp["patch_level"]) + 1, aqp_s, f"{pts['input']['points']:,}",
       f"{sizes['scanpts']:,}", pts_s, f"{sizes['scanaqp1']:,}", f"{sum(l['nodes'] for l in aqp1['levels']):,}",
       f"{sum(l['nodes'] for l in aqp['levels']):,}"))
    w("")
    rows = []
    for p in paths:
        for view in ("first", "last"):
            for ds in ("scan", "scanaqp", "scanaqp1", "scanpts"):
                c = read_jsonl_one(os.path.join(raw, "cold_%s_%s_%s.jsonl" % (ds, p, view)))
                wall = float(read(os.path.join(raw, "cold_%s_%s_%s_wall_ms.txt" % (ds, p, view))).strip())
                drawn = "%s points" % f"{c.get('points', 0):,}" if ds == "scanpts" else "%s triangles" % f"{c['triangles']:,}"
                rows.append(["%s, %s" % (p, view), names[ds], f"{c['bytes_fetched']:,}",
                             "%.1f%%" % (100 * c["bytes_fetched"] / sizes[ds]), c["requests"], drawn,
                             f"{c['gpu_bytes']:,}", "%.0f" % wall, "yes" if c["tolerance_met"] else
                             "no (%s)" % ", ".join(c["limited_by"])])
    w(md_table(["view", "format", "bytes fetched", "of its dataset", "requests", "drawn", "GPU bytes",
                "wall ms", "tolerance met"], rows))
    w("")
    # The first frame: what a client fetches before it draws the whole model (catpaq info).
    first_rows = []
    for ds in ("scan", "scanaqp", "scanaqp1", "scanpts"):
        text = read(os.path.join(raw, "info_%s.txt" % ds))
        size = re.search(r"of which (\d+) of header, metadata and index", text)
        first = re.search(r"first frame: (\d+) bytes \(the prefix, and level 0: (\d+)\)", text)
        need(size and first, "catpaq info's prefix and first frame for %s" % ds)
        total = int(first.group(1))
        first_rows.append([names[ds], f"{int(size.group(1)):,}", f"{int(first.group(2)):,}", f"{total:,}",
                           "yes" if total <= 65536 else "no"])
    w("*First frame*: what a client fetches before it draws the whole model, coarsely (`catpaq info`): "
      "the prefix (header, metadata and node index) and level 0 (CATP's root diamond, AQP's level-0 "
      "tiles, the point tree's root). The mission's bound is 64 KiB.")
    w("")
    w(md_table(["format", "prefix bytes", "level 0 bytes", "first frame bytes", "within 64 KiB"], first_rows))
    w("")
