"""Build the test FMU (an FMI 2.0 DC motor, Model Exchange and Co-Simulation) from its source.

``motor.c`` and ``modelDescription.xml`` beside this file are compiled with the system C
compiler against the FMI 2.0 headers that fmpy ships (``fmpy/c-code``) and zipped into
``motor.fmu``. The result is cached under ``$DTWIN_FMU_CACHE`` (default
``~/.cache/dtwin/fmu``) in a folder named by the hash of the sources, the headers, the
compiler's flags and version, so a second run costs a hash; nothing is written to the repository.

By hand (docs/gap.md §An FMU as a module)::

    .venv/bin/python tests/twin/fmu/build.py models/motor.fmu
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCES = (HERE / "motor.c", HERE / "modelDescription.xml")
MODEL_IDENTIFIER = "motor"
#: Compiler flags; no contraction of a multiply and an add into one rounding (FMA), so the
#: FMU's derivatives round as the expression module's do on every platform.
FLAGS = ("-shared", "-fPIC", "-O2", "-ffp-contract=off")


def compiler() -> str | None:
    """Return the C compiler to use (``$CC``, ``cc`` or ``gcc``), or None when there is none."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def _key(cc: str) -> str:
    digest = hashlib.sha256(" ".join(FLAGS).encode())
    for path in (*SOURCES, *sorted(_headers().glob("fmi2*.h"))):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    version = subprocess.run([cc, "--version"], capture_output=True, text=True, check=False)
    digest.update(version.stdout.encode())
    return digest.hexdigest()[:16]


def _cache_root() -> Path:
    return Path(os.environ.get("DTWIN_FMU_CACHE", Path.home() / ".cache" / "dtwin" / "fmu"))


def build_fmu() -> Path:
    """Return the path of the test FMU, compiling and zipping it when the cache lacks it.

    Raises
    ------
    RuntimeError
        No C compiler, or the compiler failed (its output in the message).
    """
    from fmpy import platform, sharedLibraryExtension

    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) on the PATH")
    folder = _cache_root() / _key(cc)
    fmu = folder / f"{MODEL_IDENTIFIER}.fmu"
    if fmu.is_file():
        return fmu
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        library = Path(tmp) / f"{MODEL_IDENTIFIER}{sharedLibraryExtension}"
        command = [cc, *FLAGS, "-I", str(_headers()), str(SOURCES[0]), "-o", str(library), "-lm"]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"compiling the test FMU failed: {done.stderr.strip()}")
        staged = Path(tmp) / fmu.name
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.write(SOURCES[1], "modelDescription.xml")
            archive.write(library, f"binaries/{platform}/{library.name}")
            archive.write(SOURCES[0], f"sources/{SOURCES[0].name}")
        os.replace(staged, fmu)
    return fmu


if __name__ == "__main__":
    built = build_fmu()
    if len(sys.argv) > 1:
        Path(sys.argv[1]).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built, sys.argv[1])
        built = Path(sys.argv[1])
    print(built)
