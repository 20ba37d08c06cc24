"""BTF extrapolation: from a small measured sample and four scans to a large BTF.

The compressed BTF object and its error measure live in :mod:`imagemap.btf.core`;
the scanner constraints in :mod:`imagemap.btf.constraints`; the two synthesis
methods in :mod:`imagemap.btf.extrapolate`; the Bonn UBO2014 reader and writer in
:mod:`imagemap.btf.ubo2014` (:func:`load_btf` reads either format); the scanner's
response from a colour chart in :mod:`imagemap.btf.response`; registration of the
four scans in :mod:`imagemap.btf.registration`, their lamps from the sample in
:mod:`imagemap.btf.orientation`; the paper's Table 2 in :mod:`imagemap.btf.experiment`
on the procedural materials of :mod:`imagemap.btf.materials` (made of
:mod:`imagemap.btf.procedural` noise, rendered by :mod:`imagemap.btf.rendering`); the
moving-average model in :mod:`imagemap.btf.moving_average`; photometric stereo in
:mod:`imagemap.btf.photometric` (files: :mod:`imagemap.btf.photometric_io`; heights:
:mod:`imagemap.btf.integration`). The user's document: docs/btf.md.
"""

from imagemap.btf.core import BTF, compress, directions_to_vectors, relative_error
from imagemap.btf.files import load_btf

__all__ = ["BTF", "compress", "directions_to_vectors", "load_btf", "relative_error"]
