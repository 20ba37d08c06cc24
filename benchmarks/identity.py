"""Hash a fixed set of outputs, to show that a refactor ("a pure move") changed no byte.

Makes small generated databases, runs the command line on them (depth maps at 1x and
4x, option variants, a mesh to GLB and PNG, two batches, a BTF experiment) and prints
one SHA-256 per output file. Run it before and after a change and compare:

    python benchmarks/identity.py --out /tmp/before.json
    ... change ...
    python benchmarks/identity.py --out /tmp/after.json --compare /tmp/before.json

Exit code 1 when ``--compare`` finds a difference. About 2-3 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

#: (class, objects synthesized leave-one-out at the class's default size)
ONE_X = {"fish": 4, "busts": 4, "humans": 4}
#: (class, objects synthesized at 4x the default size)
FOUR_X = {"fish": 2, "busts": 2, "humans": 2}
#: Option variants, each on the first fish.
VARIANTS = {
    "mean_vote": ["--vote", "mean"],
    "mode_vote": ["--vote", "mode"],
    "paper": ["--finish", "paper"],
    "laplacian": ["--appearance-pyramid", "laplacian"],
    "no_completion": ["--no-feature-completion"],
    "m1": ["--m", "1"],
    "exact": ["--backend", "exact"],
    "seed3": ["--seed", "3"],
}


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _run(args: list[str]) -> None:
    from imagemap.cli import main

    code = main([*args, "--quiet"])
    if code != 0:
        raise SystemExit(f"imagemap {' '.join(args)}: exit {code}")


def make_outputs(root: Path) -> dict[str, str]:
    """Write every output under ``root/out`` and return {relative path: sha256}."""
    from data_gen.dataset import write_class

    out = root / "out"
    out.mkdir()
    for name, count in ONE_X.items():
        db = root / name
        write_class(name, db, count=8, seed=0, holdout=count, quiet=True)
        for query in sorted((db / "holdout").glob("*_depth.png"))[:count]:
            stem = query.name[: -len("_depth.png")]
            target, provenance = out / f"{stem}.png", out / f"{stem}_prov.png"
            _run(["synthesize", str(query), "--db", str(db), "--preset", name,
                  "-o", str(target), "--provenance", str(provenance)])  # fmt: skip
    for name, count in FOUR_X.items():
        db = root / f"{name}4"
        default = {"fish": (200, 150)}.get(name, (150, 200))
        size = (4 * default[0], 4 * default[1])
        write_class(name, db, count=4, seed=0, holdout=count, size=size, quiet=True)
        for query in sorted((db / "holdout").glob("*_depth.png")):
            stem = query.name[: -len("_depth.png")]
            _run(["synthesize", str(query), "--db", str(db), "--preset", name,
                  "-o", str(out / f"{stem}_4x.png")])  # fmt: skip
    fish = root / "fish"
    query = sorted((fish / "holdout").glob("*_depth.png"))[0]
    for label, options in VARIANTS.items():
        _run(["synthesize", str(query), "--db", str(fish), "--preset", "fish",
              "-o", str(out / f"variant_{label}.png"), *options])  # fmt: skip
    # Meshes: one to GLB and PNG, and a batch of two.
    meshes = root / "fishm"
    write_class("fish", meshes, count=6, seed=0, holdout=2, size=(160, 120), quiet=True,
                meshes=True)  # fmt: skip
    held = sorted((meshes / "holdout" / "meshes").glob("*.glb"))
    _run(["synthesize", str(held[0]), "--db", str(meshes / "meshes"), "--preset", "fish",
          "-o", str(out / "mesh.glb")])  # fmt: skip
    _run(["synthesize", str(held[0]), "--db", str(meshes / "meshes"), "--preset", "fish",
          "-o", str(out / "mesh.png")])  # fmt: skip
    _run(["batch", str(meshes / "holdout" / "meshes"), "--db", str(meshes / "meshes"),
          "--preset", "fish", "-o", str(out / "batch_meshes"), "--workers", "1"])  # fmt: skip
    _run(["batch", str(fish / "holdout"), "--db", str(fish), "--preset", "fish",
          "-o", str(out / "batch_depths"), "--workers", "2"])  # fmt: skip
    _run(["btf", "experiment", "--out", str(out / "btf"), "--size", "64",
          "--materials", "leather", "--seed", "0"])  # fmt: skip
    # Reports hold times; the batches' done-records hold times and lock owners.
    skipped = {"batch_report.json", "table2.md", "table2.csv"}
    return {
        str(p.relative_to(out)): _digest(p)
        for p in sorted(out.rglob("*"))
        if p.is_file()
        and p.name not in skipped
        and not any(part.startswith(".imagemap") for part in p.parts)
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write the hashes here (JSON)")
    parser.add_argument("--compare", type=Path, help="hashes of an earlier run (JSON)")
    parser.add_argument("--keep", type=Path, help="make the outputs in this folder (kept)")
    args = parser.parse_args(argv)
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=False)
        hashes = make_outputs(args.keep)
    else:
        with tempfile.TemporaryDirectory() as scratch:
            hashes = make_outputs(Path(scratch))
    if args.out:
        args.out.write_text(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    print(f"{len(hashes)} outputs hashed")
    if not args.compare:
        return 0
    before = json.loads(args.compare.read_text())
    differ = sorted(k for k in before.keys() & hashes.keys() if before[k] != hashes[k])
    only = sorted(before.keys() ^ hashes.keys())
    for key in differ:
        print(f"DIFFERS  {key}")
    for key in only:
        print(f"MISSING  {key} ({'before' if key in before else 'after'} only)")
    same = len(before.keys() & hashes.keys()) - len(differ)
    print(f"{same} identical, {len(differ)} differ, {len(only)} in one run only")
    return 1 if differ or only else 0


if __name__ == "__main__":
    sys.exit(main())
