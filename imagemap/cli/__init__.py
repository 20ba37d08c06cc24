"""The ``imagemap`` command: a thin layer over the Python API.

Each topic registers its subcommands from its own module (listed in
``SUBCOMMAND_MODULES``): a module exposes ``register(subparsers)`` and sets
``func`` on each parser it adds; ``func(args)`` returns the exit code. A module
that makes a command group (``imagemap btf``) returns ``{group: subparsers}``;
the modules of ``GROUP_MODULES`` add their subcommands to that group.
A parser
that sets ``forward_unknown=True`` (``imagemap bench``) receives the arguments it
does not know itself as ``args.forwarded`` and parses them when it runs.

Building the parser imports nothing heavy: ``register`` functions must not import
NumPy, SciPy, scikit-image or numba (``imagemap --help`` and every ``COMMAND
--help`` answer at once); the ``func`` functions import what their command needs.
``imagemap COMMAND ...`` registers only that command's module (:data:`COMMANDS`): the
process that runs or explains one command does not build the others' parsers.
The colorization options come from :mod:`imagemap.depth.options` and the engine's
choices from :mod:`imagemap.core.choices`, which import nothing heavy; the preset and
method names, whose modules make dataclasses, are restated here (a test checks them
against the library).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

import imagemap
from imagemap.core.choices import APPEARANCE_PYRAMIDS, BACKENDS
from imagemap.errors import InputError

# The preset and method names below are restated, not imported: their modules make
# dataclasses (about 15 ms of every start, `imagemap synthesize --help` included). A test
# checks each against the library (tests/test_startup.py). The engine's choices come from
# :mod:`imagemap.core.choices`, which makes none.

#: The ``--preset`` choices: ``sorted(imagemap.depth.config.PRESETS)``.
PRESET_NAMES = ("busts", "fish", "humans", "shells")
#: The ``--backend`` choices.
BACKEND_NAMES = BACKENDS
#: ``imagemap.btf.extrapolate.PIXELWISE_BACKENDS``: ``btf extrapolate --backend`` choices.
PIXELWISE_BACKEND_NAMES = ("pca_kdtree", "kdtree", "exact", "pynndescent")
#: The ``imagemap evaluate --methods`` names, in report order: ``imagemap.depth.config.METHODS``.
METHOD_NAMES = (
    "full",
    "copy_nearest",
    "warp_nearest",
    "one_pass",
    "mean_vote",
    "no_position",
    "laplacian",
    "paper",
)
#: The ``--appearance-pyramid`` choices.
APPEARANCE_PYRAMID_NAMES = APPEARANCE_PYRAMIDS

SUBCOMMAND_MODULES = [
    "imagemap.cli.synthesize",
    "imagemap.cli.btf",
    "imagemap.cli.evaluate",
    "imagemap.cli.bench",
    "imagemap.cli.batch",
]

#: Modules adding subcommands to a group made by a module above: group -> modules.
GROUP_MODULES = {"btf": ["imagemap.cli.btf_ma"]}

#: Each top-level command -> the module of ``SUBCOMMAND_MODULES`` that registers it:
#: ``imagemap COMMAND ...`` builds only that module's parsers (a test checks the table
#: against the whole parser).
COMMANDS = {
    "synthesize": "imagemap.cli.synthesize",
    "db": "imagemap.cli.synthesize",
    "btf": "imagemap.cli.btf",
    "evaluate": "imagemap.cli.evaluate",
    "bench": "imagemap.cli.bench",
    "batch": "imagemap.cli.batch",
}

EPILOG = """\
examples:
  imagemap synthesize query_depth.png --db fish_db/ -o map.png --preset fish
  imagemap db check fish_db/
  imagemap evaluate fish_db/ --out report/
  imagemap btf experiment --out table2/

Run 'imagemap COMMAND --help' for the options of each command.
"""


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``imagemap`` parser: every command's, or only ``command``'s (a name of
    :data:`COMMANDS`; another name or None: every command's)."""
    modules = [COMMANDS[command]] if command in COMMANDS else SUBCOMMAND_MODULES
    parser = argparse.ArgumentParser(
        prog="imagemap",
        description=(
            "Example-based synthesis of image-maps: give the depth map of a new object and a "
            "database of similar objects with their image-maps, get a colour image-map "
            "tailored to the new object's 3D features. The same engine extrapolates measured "
            "materials (BTFs) from a small sample and four scanner images."
        ),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_VersionAction)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    groups: dict[str, argparse._SubParsersAction] = {}
    for name in modules:
        groups.update(importlib.import_module(name).register(subparsers) or {})
    for group, names in GROUP_MODULES.items():
        for name in names if group in groups else ():
            importlib.import_module(name).register(groups[group])
    return parser


def _command(argv: list[str] | None) -> str | None:
    """The command ``argv`` names: its first word that is not an option (the top-level
    options, ``--help`` and ``--version``, take no value), or None."""
    words = sys.argv[1:] if argv is None else argv
    return next((word for word in words if not word.startswith("-")), None)


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked for."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs):
        kwargs.setdefault("help", "show the version and exit")
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"imagemap {imagemap.__version__}")  # to stdout, as argparse's own action
        parser.exit()


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Options every long-running subcommand shares."""
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="no progress bar and no log lines"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log the engine's steps")


#: The ``imagemap`` program's garbage collector thresholds (``gc.set_threshold``): a
#: collection of the youngest objects every 10,000 allocations instead of 700, as numba
#: loading its cached kernels allocates many short-lived objects (290 collections, about
#: 0.15-0.3 s, in a 200x150 synthesis; 20 after); the middle generation every 100 of those
#: instead of 10: its one collection in a 200x150 or 512^2 synthesis walked the objects the
#: imports and kernel loads left, 26-51 ms of CPU (none after). Same maps and peak RSS.
GC_THRESHOLDS = (10_000, 100, 10)


def main(argv: list[str] | None = None) -> int:
    """Run a command; ``argv`` None (the ``imagemap`` program) reads ``sys.argv``."""
    if argv is None:
        gc.set_threshold(*GC_THRESHOLDS)
    try:
        return _main(argv, own_process=argv is None)
    finally:
        if argv is None:
            # The process ends next. Its last garbage collections would walk every object
            # numba made while loading kernels (about 0.7 s of a 2 s synthesis); frozen
            # objects are skipped. Outputs are written and closed by now, atexit handlers
            # still run, and only the exit is affected.
            gc.freeze()


#: Blocks at least this large get a memory mapping of their own (glibc ``mallopt``):
#: a 1024x1024 map's per-pixel arrays (4 MB), not the many smaller temporaries, which
#: would be faulted in anew each time (1 MiB: 1.0 million page faults instead of 0.47,
#: 1 s more system time, for 6 MB less peak).
_MMAP_THRESHOLD = 4 * 2**20


#: ``imagemap synthesize`` maps large blocks only for a map of this many pixels or more:
#: at 200x150 the mappings saved 3 MB and cost 0.1 s of system time (page faults of the
#: PCA samples and feature blocks, mapped anew each time).
LARGE_MAP_PIXELS = 2**20


def map_large_blocks(args: argparse.Namespace, pixels: int | None = None) -> None:
    """As the ``imagemap`` program (``args.own_process``), give large blocks their own
    mappings (see :func:`_map_large_blocks`) when ``pixels`` (the largest query) is None
    or at least ``LARGE_MAP_PIXELS``; called through :func:`main` with ``argv``, nothing."""
    if getattr(args, "own_process", False) and (pixels is None or pixels >= LARGE_MAP_PIXELS):
        _map_large_blocks()


def _map_large_blocks() -> None:
    """Give every block of ``_MMAP_THRESHOLD`` bytes or more (NumPy arrays of a large map)
    its own memory mapping, returned to the system when it is freed (glibc; elsewhere
    nothing). By default glibc raises that threshold to the largest block freed so far
    (up to 32 MB), so the engine's per-level arrays and feature blocks come from the heap
    and, once freed, stay resident beside the next level's: a 1024x1024 synthesis peaked
    about 20 MB higher (380 MB instead of 382-400). Set by the program only (it owns the
    process), not on import."""
    if not sys.platform.startswith("linux"):
        return
    import contextlib  # deferred: start-up (the parser alone needs neither)
    import ctypes  # deferred: start-up (the parser alone needs neither)

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").mallopt(-3, _MMAP_THRESHOLD)  # -3: M_MMAP_THRESHOLD


#: Optional dependencies that the libraries a synthesis imports look for at import and
#: that no part of a synthesis uses: numba reads a ``.numba_config.yaml`` with PyYAML
#: (0.02-0.05 s of CPU to import). While ``imagemap synthesize`` runs in its own process
#: it is reported missing (``sys.modules[name] = None``, taken out again after), so numba
#: takes its own fallback; PyYAML is left alone where a ``.numba_config.yaml`` is there
#: to be read.
SKIPPED_OPTIONAL_IMPORTS = ("yaml",)

#: Modules that the libraries a synthesis imports load whole although no part of a
#: synthesis uses them: SciPy's array-API layer (imported with ``scipy.ndimage``) copies
#: every NumPy attribute, which imports ``numpy.testing`` (with ``unittest``) and
#: ``numpy.f2py`` (with its Fortran parser, which looked for ``charset_normalizer``);
#: numba imports ``importlib.metadata`` (with ``email``, ``socket``, ``zipfile``: about
#: 0.02 s of CPU) for its extensions' entry points, which imagemap's kernels linked from
#: the cache do not look up (:func:`lean_kernel_loads`; numba's own path reads it as
#: before). While ``imagemap synthesize`` runs in its own process they are made lazy
#: (:class:`importlib.util.LazyLoader`): the module object is in place at once and its
#: code runs on the first attribute read, which a synthesis never makes. Not here:
#: ``numpy.ma`` (``np.median`` reads it), ``scipy.fft`` (the Poisson blend's DCTs) and
#: ``scipy.special`` (``scipy.fft`` imports names from it as it is imported). Only
#: imagemap's kernel threads run beside the main thread, and they read none of these
#: (the lazy load is thread-safe only from Python 3.12 on; on a numba version without
#: the lean loads, numba's scan reads ``importlib.metadata`` from the thread of the
#: first kernel call, and its guard lets one thread in).
LAZY_MODULES = ("numpy.testing", "numpy.f2py", "importlib.metadata")


def _defer_module(name: str) -> None:
    """Put ``name`` in ``sys.modules`` (and on its parent) as a lazy module, unless it
    is imported already or cannot be found."""
    import importlib.util  # deferred: start-up (the parser alone needs it not)

    if name in sys.modules:
        return
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
        return
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    parent, _, child = name.rpartition(".")
    setattr(sys.modules[parent], child, module)


class skip_optional_imports:
    """While active (``on``), :data:`SKIPPED_OPTIONAL_IMPORTS` not yet imported raise
    ``ImportError`` when imported; afterwards they import as before. Entering also makes
    :data:`LAZY_MODULES` not yet imported lazy; they stay so (a lazy module is the whole
    module from its first use on).

    Examples
    --------
    >>> import sys
    >>> before = {name: sys.modules.get(name) for name in SKIPPED_OPTIONAL_IMPORTS}
    >>> with skip_optional_imports(True) as skipped:
    ...     all(sys.modules[name] is None for name in skipped.names)
    True
    >>> all(sys.modules.get(name) is module for name, module in before.items())
    True
    """

    def __init__(self, on: bool) -> None:
        self.on = on
        self.names: list[str] = []
        if on:
            import os  # deferred: start-up (the parser alone needs it not)

            self.names = [
                name
                for name in SKIPPED_OPTIONAL_IMPORTS
                if name not in sys.modules
                and not (name == "yaml" and os.path.isfile(".numba_config.yaml"))
            ]

    def __enter__(self) -> skip_optional_imports:
        for name in self.names:
            sys.modules[name] = None  # type: ignore[assignment]
        if self.on:
            for name in LAZY_MODULES:
                _defer_module(name)
        return self

    def __exit__(self, *exc) -> None:
        for name in self.names:
            if name in sys.modules and sys.modules[name] is None:
                del sys.modules[name]


#: numba versions (major.minor) on which :func:`lean_kernel_loads` was checked: every
#: kernel of a synthesis loaded and the same bytes out (``benchmarks/identity.py``).
#: Elsewhere numba's own cache load runs.
LEAN_LOAD_NUMBA = ("0.68",)


def lean_kernel_loads() -> bool:
    """Load imagemap's kernels from numba's cache without numba's registry refresh.

    numba's ``Cache.load_overload`` first calls ``target_context.refresh()``, which
    imports and installs every typing and lowering registry numba has (``numba.typed``,
    ``numba.np.*``, cffi's C parser...): 0.15-0.25 s of CPU on the first kernel a process
    loads, needed to compile but not to link cached machine code. Here a cached kernel
    of imagemap's (its function in an ``imagemap.`` module) is loaded after only the
    runtime it links against is set up (``rtsys.initialize``, which numba's refresh
    does first); any other function, a kernel not in the cache (numba's compiler
    refreshes itself) or a load that fails takes numba's own path. Before a first call
    numba also runs its extensions' entry points (``entrypoints.init_all``: a scan of
    every installed package's metadata, about 0.01 s, and the import of
    ``importlib.metadata``); a kernel of imagemap's linked from the cache does not need
    them, and one not in the cache runs them before numba compiles it, as numba would.
    Set by the program for ``imagemap synthesize`` (it owns the process;
    :class:`lean_start`), not on import.

    Returns
    -------
    bool
        Whether the lean load is in place (False on numba versions not in
        :data:`LEAN_LOAD_NUMBA`).
    """
    import numba  # deferred: start-up (only a synthesis loads kernels)
    from numba.core import caching, dispatcher, entrypoints  # deferred: start-up (as above)
    from numba.core.runtime import rtsys  # deferred: start-up (as above)

    if ".".join(numba.__version__.split(".")[:2]) not in LEAN_LOAD_NUMBA:
        return False
    standard = caching.Cache.load_overload
    if getattr(standard, "imagemap_lean", False):
        return True

    def load_overload(self, sig, target_context):
        module = getattr(getattr(self, "_py_func", None), "__module__", None) or ""
        if not module.startswith("imagemap."):
            return standard(self, sig, target_context)
        try:
            rtsys.initialize(target_context)
            with self._guard_against_spurious_io_errors():
                overload = self._load_overload(sig, target_context)
        except Exception:  # numba's own load, with its refresh, decides
            return standard(self, sig, target_context)
        if overload is None:  # not in the cache: numba compiles, its extensions loaded first
            entrypoints.init_all()
        return overload

    load_overload.imagemap_lean = True  # type: ignore[attr-defined]
    caching.Cache.load_overload = load_overload  # type: ignore[method-assign]
    # numba's stubs do not declare the hook (numba 0.68: _DispatcherBase's, before a first call)
    run_entry_points = dispatcher.Dispatcher._compilation_chain_init_hook  # type: ignore[attr-defined]

    def compilation_chain_init_hook(self):
        module = getattr(getattr(self, "py_func", None), "__module__", None) or ""
        cached = isinstance(getattr(self, "_cache", None), caching.Cache)
        if not (cached and module.startswith("imagemap.")):
            run_entry_points(self)

    dispatcher.Dispatcher._compilation_chain_init_hook = compilation_chain_init_hook  # type: ignore[attr-defined]
    return True


class _AfterImport:
    """A finder on ``sys.meta_path`` that runs ``then()`` once, right after the module
    ``name`` is first imported (it wraps that module's loader, then leaves the path)."""

    def __init__(self, name: str, then) -> None:
        self.name, self.then = name, then

    def find_spec(self, fullname, path=None, target=None):
        if fullname != self.name:
            return None
        self.remove()
        from importlib.util import find_spec  # deferred: start-up (only when numba comes)

        spec = find_spec(fullname)
        loader = getattr(spec, "loader", None)
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        run = loader.exec_module

        def exec_module(module) -> None:
            run(module)
            self.then()

        loader.exec_module = exec_module
        return spec

    def remove(self) -> None:
        if self in sys.meta_path:
            sys.meta_path.remove(self)


#: SciPy versions (major.minor) on which :func:`own_scipy_docstrings` was checked: every
#: decorated function of a synthesis's SciPy modules keeps its own docstring, SciPy's
#: capabilities table is filled as before and the same bytes out
#: (``benchmarks/identity.py``). Elsewhere SciPy renders its notes as it does.
LEAN_DOCS_SCIPY = ("1.17",)

#: The SciPy modules whose decorators parse and re-render, at import, the docstring of
#: every function they decorate with numpydoc's ``FunctionDoc`` (imported there by name):
#: ``_array_api.xp_capabilities`` appends an array-API support note (213 functions in a
#: 200x150 synthesis's ``scipy.ndimage``, ``scipy.special``, ``scipy.fft``), ``_util``'s
#: batching and ``rng`` decorators a batch note (71, ``scipy.linalg``). 284 parses for
#: docstrings no part of a synthesis reads: ``import scipy.ndimage, scipy.linalg,
#: scipy.fft`` took 0.49 s of CPU with them, 0.31 without (medians of 11 fresh pairs,
#: load 4-5).
SCIPY_DOCSTRING_MODULES = ("scipy._lib._util", "scipy._lib._array_api")


class _OwnDocstring:
    """A stand-in for numpydoc's ``FunctionDoc`` in :data:`SCIPY_DOCSTRING_MODULES`'
    decorators: it parses nothing, drops the sections they add to, and renders as the
    function's own docstring (after a first line, which the decorators strip as the
    signature; they also strip the docstring's leading blank space, which
    ``inspect.cleandoc`` strips anyway, and a missing docstring becomes empty)."""

    def __init__(self, func) -> None:
        self.text = getattr(func, "__doc__", None) or ""

    def __getitem__(self, section: str) -> list:
        return []  # a fresh list: what a decorator appends to it goes nowhere

    def __str__(self) -> str:
        return "\n" + self.text


def own_scipy_docstrings(name: str) -> None:
    """Let the SciPy module ``name`` (of :data:`SCIPY_DOCSTRING_MODULES`, imported just
    now, before any module that uses its decorators) decorate functions without
    re-rendering their docstrings (:class:`_OwnDocstring`), on the SciPy versions of
    :data:`LEAN_DOCS_SCIPY`. The decorators' other work (the capabilities table, the
    batching wrappers) is unchanged. Undone by :func:`scipy_docstrings_restored`."""
    scipy = sys.modules.get("scipy")
    version = ".".join(str(getattr(scipy, "__version__", "")).split(".")[:2])
    module = sys.modules.get(name)
    if version in LEAN_DOCS_SCIPY and hasattr(module, "FunctionDoc"):
        module.FunctionDoc = _OwnDocstring  # type: ignore[union-attr]


def scipy_docstrings_restored() -> None:
    """Give :data:`SCIPY_DOCSTRING_MODULES` their ``FunctionDoc`` back: functions SciPy
    decorates from now on get its notes (those decorated meanwhile keep their own)."""
    for name in SCIPY_DOCSTRING_MODULES:
        module = sys.modules.get(name)
        if getattr(module, "FunctionDoc", None) is _OwnDocstring:
            module.FunctionDoc = sys.modules["scipy._lib._docscrape"].FunctionDoc  # type: ignore[union-attr]


class lean_start:
    """The start-up of ``imagemap synthesize`` in its own process: three tweaks, one reason.

    The program runs one command and then ends, so it may set what an importing library
    must not: while this is active (``on``), the optional imports no part of a synthesis
    uses are reported missing and the unused modules made lazy
    (:class:`skip_optional_imports`); SciPy's decorators leave the docstrings of the
    functions they decorate as they are (:func:`own_scipy_docstrings`, installed as
    each of :data:`SCIPY_DOCSTRING_MODULES` is imported); and imagemap's kernels are
    linked from numba's cache without numba's registry refresh
    (:func:`lean_kernel_loads`, installed as soon as numba is imported: a command that
    stops at bad input before the engine is imported does not pay for numba's import).
    They are for the depth maps and the meshes alike (the mesh route's outputs checked the
    same bytes both ways in fresh processes). Afterwards the optional imports import as
    before and SciPy renders its docstrings again; the lean kernel loads stay (the process
    ends).

    Parameters
    ----------
    on : bool
        Set by :func:`_main` for ``imagemap synthesize`` run as the program (``main()``
        without ``argv``); otherwise nothing changes.
    """

    def __init__(self, on: bool) -> None:
        self.skip = skip_optional_imports(on)
        self.hooks: list[_AfterImport] = []
        if on:
            if "numba" in sys.modules:
                lean_kernel_loads()
            else:
                self.hooks.append(_AfterImport("numba", lean_kernel_loads))
            # A module imported already has decorated its functions: nothing to skip.
            self.hooks += [
                _AfterImport(name, lambda name=name: own_scipy_docstrings(name))
                for name in SCIPY_DOCSTRING_MODULES
                if name not in sys.modules
            ]

    def __enter__(self) -> lean_start:
        self.skip.__enter__()
        sys.meta_path[:0] = self.hooks
        return self

    def __exit__(self, *exc) -> None:
        for hook in self.hooks:
            hook.remove()
        scipy_docstrings_restored()
        self.skip.__exit__(*exc)


def _record_given(parser: argparse.ArgumentParser) -> None:
    """Make every action of ``parser`` (and its subcommands') note its destination in the
    namespace's ``_given`` set when the command line invokes it."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for subparser in action.choices.values():
                _record_given(subparser)
            continue
        base = type(action)

        # A subclass of each action's own class, made at run time: mypy cannot check a base
        # held in a variable.
        class Recorded(base):  # type: ignore[misc,valid-type]
            def __call__(self, parser, namespace, values, option_string=None):
                namespace.__dict__.setdefault("_given", set()).add(self.dest)
                return super().__call__(parser, namespace, values, option_string)

        action.__class__ = Recorded


def _given_options(argv: list[str] | None) -> frozenset[str]:
    """The destinations of the options the command line gives itself (not their defaults):
    a command refuses an option that does not apply to its input, and two that conflict,
    whatever their order (``--views A --view B``)."""
    parser = build_parser(_command(argv))
    _record_given(parser)
    try:
        namespace, _ = parser.parse_known_args(argv)
    except SystemExit:  # parsed once already; kept safe
        return frozenset()
    return frozenset(getattr(namespace, "_given", ()))


def _main(argv: list[str] | None, own_process: bool = False) -> int:
    parser = build_parser(_command(argv))
    try:
        args, unknown = parser.parse_known_args(argv)
        if getattr(args, "forward_unknown", False):
            args.forwarded = unknown
        elif unknown:  # what parse_args would say
            parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    except SystemExit as exc:
        if exc.code == 2:  # argparse printed the error naming the option: exit code 2
            return 2
        raise  # --help, --version
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    import logging  # deferred: start-up (not needed by --help)

    level = logging.WARNING
    if getattr(args, "verbose", False):
        level = logging.INFO
    if getattr(args, "quiet", False):
        level = logging.ERROR
    logging.basicConfig(level=level, format="imagemap: %(message)s", stream=sys.stderr)
    args.own_process = own_process
    args.given = _given_options(argv)
    if args.command != "synthesize":  # synthesize decides by the map's size
        map_large_blocks(args)
    try:
        with lean_start(own_process and args.command == "synthesize"):
            return int(args.func(args) or 0)
    except InputError as exc:
        print(f"imagemap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("imagemap: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
