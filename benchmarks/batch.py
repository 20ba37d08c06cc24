"""Batch throughput and what preparing the database once saves, printed (not asserted).

    python -m data_gen fish --count 24 --holdout 12 --meshes --out fish24
    python benchmarks/batch.py fish24 [--workers 2] [--skip-dask]

Measures, on the holdout meshes (textured GLB out) and the holdout depth maps (PNG
out): objects per minute with the local pool and with a 2-worker Dask LocalCluster
(processes), and per object what a worker would pay without the shipped, prepared
database (opening and reading the database; rendering mesh examples without and with
the disk cache), beside what is still built per object inside ``colorize`` (the
chosen examples' pyramids).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path


def _throughput(inputs, db, options, **kwargs) -> dict:
    from imagemap.batch import run_batch

    out = Path(tempfile.mkdtemp(prefix="imagemap-bench-"))
    try:
        summary = run_batch(inputs, db, out, options, **kwargs)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return {
        "done": summary.done,
        "failed": summary.failed,
        "seconds": round(summary.seconds, 2),
        "prepare_seconds": round(summary.prepare_seconds, 2),
        "objects_per_minute": round(summary.per_minute, 1),
    }


def _per_object_costs(root: Path) -> dict:
    import numpy as np

    from imagemap.database import Database
    from imagemap.depth.guides import example_mappings, pyramid_levels
    from imagemap.io import read_depth

    def load_all(database):
        for example in database:
            _ = example.depth, example.image

    costs = {}
    start = time.perf_counter()
    load_all(Database.from_directory(root))
    costs["open_and_read_picture_db_s"] = time.perf_counter() - start
    cache = Path(tempfile.mkdtemp(prefix="imagemap-cache-"))
    os.environ["IMAGEMAP_CACHE"] = str(cache)
    try:
        start = time.perf_counter()
        load_all(Database.from_directory(root / "meshes"))
        costs["render_mesh_db_uncached_s"] = time.perf_counter() - start
        start = time.perf_counter()
        load_all(Database.from_directory(root / "meshes"))
        costs["read_mesh_db_from_cache_s"] = time.perf_counter() - start
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    database = Database.from_directory(root)
    depth = read_depth(sorted((root / "holdout").glob("*_depth.png"))[0])
    levels = pyramid_levels(depth > 0, (7, 11, 9))
    start = time.perf_counter()
    for example in list(database)[:2]:
        example_mappings(example, levels)
    costs["chosen_examples_pyramids_m2_s"] = time.perf_counter() - start
    costs["examples"] = len(database)
    return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in costs.items()} | {
        "_note": "pyramids of the m=2 chosen examples are still built inside colorize: "
        + str(np.round(costs["chosen_examples_pyramids_m2_s"], 3))
        + " s per object"
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="a data_gen class written with --holdout --meshes")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--preset", default="fish")
    parser.add_argument("--skip-dask", action="store_true")
    args = parser.parse_args()
    from imagemap.batch import BatchOptions

    options = BatchOptions(preset=args.preset)
    meshes, mesh_db = args.root / "holdout" / "meshes", args.root / "meshes"
    depths = Path(tempfile.mkdtemp(prefix="imagemap-depths-"))
    for path in (args.root / "holdout").glob("*_depth.png"):
        shutil.copy(path, depths)
    results = {"per_object_costs": _per_object_costs(args.root)}
    print(json.dumps(results, indent=1), flush=True)
    cache = Path(tempfile.mkdtemp(prefix="imagemap-cache-"))
    os.environ["IMAGEMAP_CACHE"] = str(cache)
    results["warm_up"] = _throughput(meshes, mesh_db, options, workers=1)  # fills the cache
    for label, inputs, db in (("meshes", meshes, mesh_db), ("depth_maps", depths, args.root)):
        results[f"{label}_in_process"] = _throughput(inputs, db, options, workers=1)
        results[f"{label}_pool_{args.workers}"] = _throughput(
            inputs, db, options, workers=args.workers
        )
        if not args.skip_dask:
            from dask.distributed import LocalCluster

            with LocalCluster(
                n_workers=args.workers, threads_per_worker=1, dashboard_address=None
            ) as cluster:
                results[f"{label}_dask_local_cluster_{args.workers}"] = _throughput(
                    inputs, db, options, scheduler=cluster.scheduler_address
                )
        print(json.dumps(results, indent=1), flush=True)
    shutil.rmtree(cache, ignore_errors=True)
    shutil.rmtree(depths, ignore_errors=True)


if __name__ == "__main__":
    main()
