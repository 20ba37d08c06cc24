"""``python -m data_gen CLASS --count N --size WxH --seed S --out DIR [--holdout K] [--meshes]``."""

from __future__ import annotations

import argparse
import logging
import sys
import time

from data_gen import CLASSES
from data_gen.dataset import write_class
from data_gen.render import ray_backend
from imagemap.io import InputError
from imagemap.validate import non_negative_int, parse_size


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m data_gen",
        description=(
            "Make a class of procedural objects and render each to a depth map, an "
            "image-map and a part-label map (an imagemap database)."
        ),
        epilog="example: python -m data_gen fish --count 9 --holdout 1 --out examples/fish",
    )
    parser.add_argument("class_name", metavar="CLASS", choices=sorted(CLASSES))
    parser.add_argument("--count", type=int, default=20, help="instances (default 20)")
    parser.add_argument(
        "--size",
        type=parse_size,
        default=None,
        help="WIDTHxHEIGHT (default: fish and shells 200x150, busts and humans 150x200)",
    )
    parser.add_argument(
        "--seed", type=non_negative_int, default=0, help="run seed >= 0 (default 0)"
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--holdout",
        type=int,
        default=0,
        help="write the last K instances to OUT/holdout/ (queries kept out of the database)",
    )
    parser.add_argument(
        "--meshes",
        action="store_true",
        help="also write each instance as a textured mesh OUT/meshes/NAME.glb "
        "(holdout: OUT/holdout/meshes/), for imagemap's mesh input and batches",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run in --out made at other settings (--seed, --size, "
        "--count, --holdout, --meshes): its files are replaced and those this run does not "
        "write are removed. Without it such a folder is refused; a folder of the same "
        "settings is made anew either way",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no log")
    return parser


#: What ``write_class`` writes into --out (besides ``contact_sheet.png`` and the
#: ``holdout/`` and ``meshes/`` folders of the same): CLASS_NNN + a suffix.
_OURS = (
    r"^{cls}_\d{{3,}}"
    r"(?:_(?:depth|image|labels|normal|roughness|metallic|height|ao))?\.(?:png|json)$"
)


def check_out_holds_only_ours(out: str, class_name: str) -> list:
    """Refuse an --out folder holding anything this command would not write itself (a
    database of other examples, a user's folder): it would be mixed with, or partly
    replaced by, the new instances. Returns the files of an earlier run of the same
    class there (relative to ``out``; :func:`check_earlier_run` compares its settings)."""
    import re
    from pathlib import Path

    from imagemap.io import is_temporary

    root = Path(out)
    if not root.is_dir():
        return []
    ours = re.compile(_OURS.format(cls=re.escape(class_name)))
    mesh = re.compile(rf"^{re.escape(class_name)}_\d{{3,}}\.glb$")

    def foreign(folder: Path, depth: int) -> Path | None:
        for entry in sorted(folder.iterdir()):
            if entry.is_dir() and depth == 0 and entry.name in ("holdout", "meshes"):
                found = foreign(entry, 1 if entry.name == "holdout" else 2)
                if found is not None:
                    return found
                continue
            if entry.is_dir() and depth == 1 and entry.name == "meshes":
                if (found := foreign(entry, 2)) is not None:
                    return found
                continue
            name = entry.name
            if entry.is_file() and (
                (depth < 2 and ours.match(name))
                or (depth == 2 and mesh.match(name))
                or (depth == 0 and name == "contact_sheet.png")
                or is_temporary(entry)
            ):
                continue
            return entry
        return None

    if (found := foreign(root, 0)) is not None:
        raise InputError(
            f"--out {out}: holds {found}, which this command does not write: the folder is "
            f"someone's data (a database or your files), not an earlier {class_name} run; "
            "give a new or empty folder"
        )
    return sorted(
        p.relative_to(root) for p in root.rglob("*") if p.is_file() and not is_temporary(p)
    )


def check_earlier_run(args: argparse.Namespace, existing: list) -> list:
    """Refuse, unless ``--overwrite``, an --out folder holding an earlier run made at other
    settings (:func:`data_gen.dataset.compare_run`), saying what would be replaced and
    what left. Returns the earlier run's files this run does not write (with
    ``--overwrite``: removed once the new run is written, so the folder is one run's)."""
    from data_gen import CLASSES
    from data_gen.dataset import compare_run

    if not existing:
        return []
    size = args.size or CLASSES[args.class_name].default_size
    replaced, left, why = compare_run(
        args.out,
        existing,
        args.class_name,
        count=args.count,
        seed=args.seed,
        size=size,
        holdout=args.holdout,
        meshes=args.meshes,
    )
    if not why or args.overwrite:
        return left if why else []
    shown = ", ".join(str(p) for p in replaced[:4]) + (" ..." if len(replaced) > 4 else "")
    raise InputError(
        f"--out {args.out}: holds an earlier {args.class_name} run at other settings ({why}); "
        f"this run would replace {len(replaced)} of its files ({shown or 'none'}) and leave "
        f"{len(left)} beside the new ones: a mixed database. Give a new folder, or "
        "--overwrite to replace the earlier run whole"
    )


#: Peak bytes per pixel of one instance while a class is made, measured (VmHWM, count 1):
#: fish 722 bytes/pixel from 800x600 to 1600x1200 (567 MB, 1.58 GB), busts at 800x600
#: 992 MB (about 1,800 above the start-up); shells (a 60,000-face mesh, whose ray cast
#: holds a candidate per face and pixel it may cover) 3,700 at 400x300 (555 MB), 2,400 at
#: 800x600 (1.26 GB), 1,900 at 1600x1200 (3.73 GB); bounded by shells' from 800x600 on.
_INSTANCE_PIXEL_BYTES = 2500
#: Kept per instance until the contact sheet is drawn (depth, image, labels, PBR maps).
_KEPT_PIXEL_BYTES = 64


def check_memory_for(class_name: str, count: int, size) -> None:
    """Refuse a --size (and --count) the memory this process may use cannot hold."""
    from data_gen import CLASSES
    from imagemap.memory import check_memory

    width, height = size or CLASSES[class_name].default_size
    pixels = int(width) * int(height)
    one = pixels * _INSTANCE_PIXEL_BYTES
    kept = pixels * _KEPT_PIXEL_BYTES * max(int(count), 1)
    if kept > one:  # the instances kept for the contact sheet weigh most: --count's doing
        what = f"--count {count} at --size {width}x{height} (each kept for the contact sheet)"
        check_memory(one + kept, what, advice="give a smaller --count (or --size)")
    else:
        check_memory(one + kept, f"--size {width}x{height}", advice="give a smaller --size")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.ERROR if args.quiet else logging.INFO,
        format="data_gen: %(message)s",
        stream=sys.stderr,
    )
    start = time.perf_counter()
    try:
        from imagemap.outputs import check_output_directory

        check_output_directory(args.out, "--out directory")
        existing = check_out_holds_only_ours(args.out, args.class_name)
        check_memory_for(args.class_name, args.count, args.size)
        stale = check_earlier_run(args, existing)
        instances = write_class(
            CLASSES[args.class_name],
            args.out,
            count=args.count,
            seed=args.seed,
            size=args.size,
            holdout=args.holdout,
            quiet=args.quiet,
            meshes=args.meshes,
        )
    except InputError as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 2
    _remove_stale(args.out, stale, args.quiet)
    if not args.quiet:
        print(
            f"data_gen: {len(instances)} {args.class_name} written to {args.out} in "
            f"{time.perf_counter() - start:.1f} s (ray backend {ray_backend()})",
            file=sys.stderr,
        )
    return 0


def _remove_stale(out: str, stale: list, quiet: bool) -> None:
    """Remove the earlier run's files this run did not write (``--overwrite``), and the
    folders that leaves empty."""
    from pathlib import Path

    root = Path(out)
    for relative in stale:
        (root / relative).unlink(missing_ok=True)
    for folder in sorted({(root / p).parent for p in stale}, key=lambda p: -len(p.parts)):
        if folder != root and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    if stale and not quiet:
        print(
            f"data_gen: --overwrite: removed {len(stale)} file(s) of the earlier run "
            f"({', '.join(str(p) for p in stale[:3])}{' ...' if len(stale) > 3 else ''})",
            file=sys.stderr,
        )


if __name__ == "__main__":
    sys.exit(main())
