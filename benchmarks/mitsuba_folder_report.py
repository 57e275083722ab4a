"""Does volcl open, render and agree with Mitsuba 3 on every scene of a folder?

    python benchmarks/mitsuba_folder_report.py FOLDER_OR_FILE... [--spp 64] [--max-size 160]
        [--seeds 0 1] [--out DIR] [--markdown REPORT.md] [--mitsuba-python PY] [--variant V]

Every .xml file under the folders (and every file named) is a candidate; files that another candidate includes, files
whose root is not <scene>, and scenes with neither a shape nor an include (parameter or material
files) are listed as fragments and not rendered on their own. For each
scene:
  1. volcl loads it (warnings counted; an error is reported with the element it names);
  2. Mitsuba 3 loads and renders it (in a subprocess, benchmarks/mitsuba_ref.py);
  3. where both can, each renders two seeds at --spp with the film scaled down by a whole factor
     so that its longer side is at most --max-size pixels (same aspect ratio, same field of view in
     both), and ../shared/tools/compare_renders.py judges whether volcl's pair estimates Mitsuba's
     image: R (about 1 when both estimate the same image), the largest per-channel |z| of the image
     means, and PASS or FAIL.
It prints a Markdown table (also written to --markdown) with a row per file and a closing count.
Without Mitsuba the Mitsuba columns say so and nothing is compared.
"""
from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
import mitsuba_ref  # noqa: E402
from common import log  # noqa: E402

DEFAULT_TOOL = ROOT.parent / "shared" / "tools" / "compare_renders.py"
_INCLUDE = re.compile(r"<include\s+[^>]*filename\s*=\s*[\"']([^\"']+)[\"']")
_COMMENT = re.compile(r"<!--.*?-->", re.S)



@dataclass
class Row:
    file: str
    volcl: str = ""
    mitsuba: str = ""
    agreement: str = ""
    verdict: str = ""        # 'PASS', 'FAIL', 'volcl error', 'Mitsuba error', 'fragment', ...


def candidates(folders):
    files = sorted({p.resolve() for f in folders
                    for p in ([Path(f)] if Path(f).is_file() else Path(f).rglob("*.xml"))})
    included = {}
    for path in files:
        text = _COMMENT.sub("", path.read_text(errors="replace"))
        for name in _INCLUDE.findall(text):
            included.setdefault((path.parent / name).resolve(), path)
    return files, included


def short_error(message: str) -> str:
    """The part of a volcl or Mitsuba error a table can hold: what failed, not where."""
    message = " ".join(message.split())
    for pattern in (r"(uses undefined parameter \$\w+)", r"unknown (\w+) type '([^']+)'", r"(conductor material '[^']+' is not supported)", r"(unknown parameter '[^']+' for <[^>]+>)",
                    r"(instancing \([^)]*\) is not supported yet)", r"(cannot load \w+ '[^']+': file not found)",
                    r"(<\w+> is not allowed inside <[^>]+>)"):
        m = re.search(pattern, message)
        if m:
            return f"{m.group(1)} '{m.group(2)}'" if m.lastindex == 2 else m.group(1)
    tail = message.split(": ")[-1] if ": " in message else message
    return tail[:110]


def film_size(width: int, height: int, limit: int) -> tuple[int, int]:
    """The film scaled down by the smallest whole factor that divides both sides and brings the
    longer one to at most `limit` (so the aspect ratio, and with it the field of view, is exact)."""
    g = math.gcd(width, height)
    for k in range(1, g + 1):
        if g % k == 0 and max(width, height) // k <= limit:
            return width // k, height // k
    return width // g, height // g


def render_volcl(scene_path, out, spp, seed, size, device):
    from volcl.image import write_image
    from volcl.renderer import Renderer
    from volcl.scene import load
    scene = load(scene_path)
    scene.camera.width, scene.camera.height = size
    r = Renderer(scene, device=device, seed=seed)
    res = r.render(spp)
    write_image(out, res.image, {"spp": res.spp}, {"variance": res.variance})
    return res


def report_scene(path: Path, args, mts, tool, out_dir, device) -> Row:
    from volcl.errors import VolclError
    from volcl.scene import load
    row = Row(str(path.relative_to(args.base)) if args.base else str(path))
    try:
        scene = load(path)
        row.volcl = f"loads ({len(scene.warnings)} warning{'s' if len(scene.warnings) != 1 else ''})"
    except VolclError as exc:
        row.volcl, row.verdict, scene = "error: " + short_error(str(exc)), "volcl error", None
    except Exception as exc:             # a crash is a volcl bug: report it as one
        row.volcl, row.verdict, scene = f"crash: {type(exc).__name__}: {exc}"[:120], "volcl crash", None
    if mts is None:
        row.mitsuba = "not run (Mitsuba 3 not found)"
        return row
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", row.file)
    refs = [out_dir / f"{name}_mitsuba_s{s}.exr" for s in args.seeds]
    t0 = time.perf_counter()
    try:
        if scene is None:
            # only whether Mitsuba can render it at all: one sample per pixel of a small film
            mitsuba_ref.render_mitsuba(str(path), None, mts["python"], args.variant, 1, 0, repeat=1,
                                       warmup=False, size=(16, 16), timeout=1800)
            row.mitsuba = "renders"
            return row
        size = film_size(scene.camera.width, scene.camera.height, args.max_size)
        for s, ref in zip(args.seeds, refs):
            mitsuba_ref.render_mitsuba(str(path), str(ref), mts["python"], args.variant, args.spp, s,
                                       repeat=1, warmup=False, size=size, timeout=1800)
        row.mitsuba = f"renders ({time.perf_counter() - t0:.1f} s)"
    except mitsuba_ref.MitsubaError as exc:
        lines = [ln for ln in str(exc).splitlines() if ln.strip()]
        row.mitsuba = "error: " + short_error(lines[-1] if lines else str(exc))
        if scene is not None:
            row.verdict = "Mitsuba error"
        return row
    tests = [out_dir / f"{name}_volcl_s{s}.exr" for s in args.seeds]
    t0 = time.perf_counter()
    try:
        invalid = sum(render_volcl(path, t, args.spp, s, size, device).invalid for s, t in zip(args.seeds, tests))
    except Exception as exc:
        row.agreement, row.verdict = f"volcl render failed: {exc}"[:120], "volcl error"
        return row
    row.volcl += f", renders ({time.perf_counter() - t0:.1f} s)"
    proc = subprocess.run([sys.executable, str(tool), *map(str, refs), *map(str, tests), "--name", name],
                          capture_output=True, text=True)
    last = (proc.stdout.strip().splitlines() or ["FAIL no output"])[-1]
    m = re.search(r"R=([0-9.]+) max\|z\|=([0-9.]+|nan)", last)
    row.verdict = "PASS" if last.startswith("PASS") else "FAIL"
    row.agreement = (f"R = {m.group(1)}, max abs z = {m.group(2)}" if m else last) + \
        (f", {invalid} invalid samples" if invalid else "") + f" ({size[0]}x{size[1]}, {args.spp} spp)"
    return row


def markdown(rows, absent, header) -> str:
    lines = [header, "", "| file | volcl | Mitsuba 3 | agreement | verdict |", "|---|---|---|---|---|"]
    for r in rows:
        cells = [r.file, r.volcl, r.mitsuba, r.agreement, r.verdict]
        lines.append("| " + " | ".join(c.replace("|", "/") for c in cells) + " |")
    counts = {}
    for r in rows:
        counts[r.verdict] = counts.get(r.verdict, 0) + 1
    lines += ["", "Totals: " + ", ".join(f"{v or 'not compared'}: {n}" for v, n in sorted(counts.items()))]
    if absent:
        lines += ["", "Not in the snapshot (large files kept outside git, e.g. Git LFS): " + ", ".join(absent)]
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", nargs="+")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--max-size", type=int, default=160, help="longest film side rendered (default 160)")
    p.add_argument("--seeds", type=int, nargs=2, default=[0, 1])
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--out", help="folder for the EXRs (default: a new temporary folder)")
    p.add_argument("--markdown", help="also write the table here")
    p.add_argument("--base", help="name files relative to this folder (default: the common folder)")
    p.add_argument("--absent", nargs="*", default=[], help="files of the source that are missing, to list")
    p.add_argument("--compare-tool", default=str(DEFAULT_TOOL))
    p.add_argument("--device", help="volcl device selector")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)

    files, included = candidates(args.folders)
    if not files:
        print("no .xml files found")
        return 2
    import os
    args.base = Path(args.base).resolve() if args.base else Path(os.path.commonpath([f.parent for f in files]))
    mts = mitsuba_ref.locate(args.mitsuba_python, args.variant, log=log)
    tool = Path(args.compare_tool)
    if mts is not None and not tool.is_file():
        print(f"error: comparison tool {tool} not found (pass --compare-tool)")
        return 2
    out_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="volcl-folder-report-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    from volcl import device as devmod
    device = devmod.choose(args.device)
    rows = []
    for path in files:
        root = path.read_text(errors="replace")
        rel = str(path.relative_to(args.base))
        if path in included:
            rows.append(Row(rel, verdict="fragment",
                            volcl=f"included by {included[path].relative_to(args.base)}"))
            continue
        text = _COMMENT.sub("", root)
        if not re.search(r"<scene[\s>]", text):
            rows.append(Row(rel, verdict="fragment", volcl="not a scene (its root is not <scene>)"))
            continue
        if not re.search(r"<(shape|include)[\s>/]", text):
            rows.append(Row(rel, verdict="fragment", volcl="no shapes and no includes: a part of other scenes"))
            continue
        log(f"{rel} ...")
        rows.append(report_scene(path, args, mts, tool, out_dir, device))
        log(f"  {rows[-1].verdict or '-'}: {rows[-1].volcl} | {rows[-1].mitsuba} | {rows[-1].agreement}")
        if args.markdown:       # the table so far, so that a run stopped early keeps what it finished
            partial = f"{_header(args, mts, device, out_dir)}; partial: {len(rows)} of {len(files)} files"
            Path(args.markdown).write_text(markdown(rows, args.absent, partial) + "\n")
    text = markdown(rows, args.absent, _header(args, mts, device, out_dir))
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


def _header(args, mts, device, out_dir) -> str:
    where = f"Mitsuba {mts['version']} {args.variant}" if mts else "no Mitsuba"
    return (f"volcl on {device.key} {device.name} against {where}; {args.spp} spp, seeds {args.seeds[0]} and "
            f"{args.seeds[1]}, films scaled to at most {args.max_size} px; EXRs in {out_dir}")


if __name__ == "__main__":
    sys.exit(main())
