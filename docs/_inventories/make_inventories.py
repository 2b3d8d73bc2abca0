"""Write the small intersphinx inventories the documentation links numpy, scipy and Python with.

The build runs offline (the machines it runs on reach no documentation site), so instead of
downloading each project's ``objects.inv`` it reads these three, made here from the names the
documentation refers to. Each entry points at the page the real inventory names: numpy's and
scipy's generated API pages (``reference/generated/<name>.html``), Python's library pages.
Add a name here when a page or docstring links one that is missing, then run::

    python docs/_inventories/make_inventories.py      # needs sphobjinv (pip install sphobjinv)

and commit the three ``.inv`` files.
"""

from __future__ import annotations

from pathlib import Path

import sphobjinv as soi

HERE = Path(__file__).resolve().parent

#: (name, domain:role, page or None for the generated API page, display name or None)
_R = "reference/random/"
NUMPY = [
    ("numpy", "py:module", "index.html", "-"),
    ("numpy.ndarray", "py:class", None, None),
    ("numpy.random.Generator", "py:class", _R + "generator.html#numpy.random.Generator", None),
    ("numpy.random.RandomState", "py:class", _R + "legacy.html#numpy.random.RandomState", None),
    ("numpy.random.default_rng", "py:function", _R + "generator.html#$", None),
    ("numpy.float64", "py:attribute", "reference/arrays.scalars.html#numpy.float64", None),
    ("numpy.int16", "py:attribute", "reference/arrays.scalars.html#numpy.int16", None),
    ("numpy.inf", "py:data", "reference/constants.html#numpy.inf", None),
    ("numpy.nan", "py:data", "reference/constants.html#numpy.nan", None),
    ("numpy.loadtxt", "py:function", None, None),
    ("numpy.load", "py:function", None, None),
    ("numpy.linalg.eigh", "py:function", None, None),
    ("numpy.linalg.inv", "py:function", None, None),
    ("numpy.linalg.norm", "py:function", None, None),
    ("numpy.linalg.svd", "py:function", None, None),
    ("numpy.linalg.lstsq", "py:function", None, None),
    ("numpy.polyfit", "py:function", None, None),
    ("numpy.trapezoid", "py:function", None, None),
    ("numpy.ascontiguousarray", "py:function", None, None),
    ("numpy.matmul", "py:data", "reference/generated/numpy.matmul.html#numpy.matmul", None),
    ("array_like", "std:term", "glossary.html#term-array_like", "array_like"),
    ("arrays.scalars", "std:label", "reference/arrays.scalars.html#arrays-scalars", "Scalars"),
]

SCIPY = [
    ("scipy", "py:module", "index.html", "-"),
    ("scipy.optimize.least_squares", "py:function", None, None),
    ("scipy.optimize.nnls", "py:function", None, None),
    ("scipy.linalg.sqrtm", "py:function", None, None),
    ("scipy.io.loadmat", "py:function", None, None),
    ("scipy.spatial.transform.Rotation", "py:class", None, None),
    ("scipy.signal.welch", "py:function", None, None),
]

_A = "library/collections.abc.html#collections.abc."
_F = "library/functions.html#"
_T = "library/stdtypes.html#"
_E = "library/exceptions.html#"
_G = "glossary.html#term-"
PYTHON = [
    ("int", "py:class", _F + "int", None),
    ("float", "py:class", _F + "float", None),
    ("bool", "py:class", _F + "bool", None),
    ("str", "py:class", _T + "str", None),
    ("bytes", "py:class", _T + "bytes", None),
    ("dict", "py:class", _T + "dict", None),
    ("list", "py:class", _T + "list", None),
    ("tuple", "py:class", _T + "tuple", None),
    ("object", "py:class", _F + "object", None),
    ("callable", "py:function", _F + "callable", None),
    ("None", "py:data", "library/constants.html#None", None),
    ("True", "py:data", "library/constants.html#True", None),
    ("False", "py:data", "library/constants.html#False", None),
    ("ValueError", "py:exception", _E + "ValueError", None),
    ("OSError", "py:exception", _E + "OSError", None),
    ("Exception", "py:exception", _E + "Exception", None),
    ("UserWarning", "py:exception", _E + "UserWarning", None),
    ("Warning", "py:exception", _E + "Warning", None),
    ("KeyboardInterrupt", "py:exception", _E + "KeyboardInterrupt", None),
    ("pathlib.Path", "py:class", "library/pathlib.html#pathlib.Path", None),
    ("os.PathLike", "py:class", "library/os.html#os.PathLike", None),
    ("argparse.ArgumentParser", "py:class", "library/argparse.html#argparse.ArgumentParser",
     None),
    ("collections.abc.Sequence", "py:class", _A + "Sequence", None),
    ("collections.abc.Mapping", "py:class", _A + "Mapping", None),
    ("collections.abc.Iterable", "py:class", _A + "Iterable", None),
    ("collections.abc.Iterator", "py:class", _A + "Iterator", None),
    ("collections.abc.Callable", "py:class", _A + "Callable", None),
    ("collections.namedtuple", "py:function", "library/collections.html#$", None),
    ("contextlib.contextmanager", "py:function", "library/contextlib.html#$", None),
    ("dataclasses.dataclass", "py:function", "library/dataclasses.html#$", None),
    ("dataclasses.replace", "py:function", "library/dataclasses.html#$", None),
    ("warnings.warn", "py:function", "library/warnings.html#warnings.warn", None),
    ("concurrent.futures.ThreadPoolExecutor", "py:class",
     "library/concurrent.futures.html#concurrent.futures.ThreadPoolExecutor", None),
    ("bltin-boolean-values", "std:label", _T + "bltin-boolean-values", "Boolean Type - bool"),
    ("sequence", "std:term", _G + "sequence", "sequence"),
    ("iterable", "std:term", _G + "iterable", "iterable"),
    ("iterator", "std:term", _G + "iterator", "iterator"),
    ("generator", "std:term", _G + "generator", "generator"),
    ("mapping", "std:term", _G + "mapping", "mapping"),
    ("path-like object", "std:term", _G + "path-like-object", "path-like object"),
    ("file object", "std:term", _G + "file-object", "file object"),
]


def inventory(project: str, version: str, entries, generated: str) -> soi.Inventory:
    inv = soi.Inventory()
    inv.project, inv.version = project, version
    for name, role, uri, disp in entries:
        domain, role = role.split(":")
        if uri is None:  # the API page a name of numpy or scipy has
            uri = f"{generated}{name}.html#{name}"
        uri = uri.replace("#$", "#" + name)
        if uri.endswith("#" + name):
            uri = uri[: -len(name)] + "$"  # the inventory's shorthand for "#" + name
        inv.objects.append(soi.DataObjStr(name=name, domain=domain, role=role, priority="1",
                                          uri=uri, dispname=disp or "-"))
    return inv


def main() -> None:
    for fname, project, version, entries, generated in [
        ("numpy.inv", "NumPy", "2.3", NUMPY, "reference/generated/"),
        ("scipy.inv", "SciPy", "1.16", SCIPY, "reference/generated/"),
        ("python.inv", "Python", "3.13", PYTHON, ""),
    ]:
        inv = inventory(project, version, entries, generated)
        soi.writebytes(HERE / fname, soi.compress(inv.data_file(contract=True)))
        print(f"{fname}: {len(inv.objects)} names")


if __name__ == "__main__":
    main()
