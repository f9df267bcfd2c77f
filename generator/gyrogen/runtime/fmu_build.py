"""An FMU for this machine: the FMU's sources (codegen/fmu.py) compiled by
gcc into a shared library against the FMI headers FMPy ships, and packed
with them into <prefix>.fmu (a zip; the same bytes for the same scene)."""

from __future__ import annotations

import io
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from gyrogen.codegen import fmu
from gyrogen.codegen.fmu_model import FmuModel
from gyrogen.errors import GyrogenError
from gyrogen.runtime import cache, flags
from gyrogen.runtime.build import require

_EXTENSIONS = {"linux": ".so", "darwin": ".dylib"}
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)
"""Every member's timestamp: the zip depends on the contents alone."""


def fmi_headers() -> Path:
    """The directory of FMPy's copy of the FMI 2.0 headers."""
    try:
        import fmpy
    except ImportError as exc:
        raise GyrogenError(
            "building an FMU needs the FMI headers, taken from FMPy, which is not installed: "
            "pip install fmpy (or gyrogen's fmu extra)"
        ) from exc
    where = Path(fmpy.__file__).parent / "c-code"
    if not (where / "fmi2Functions.h").is_file():
        raise GyrogenError(f"FMPy {fmpy.__version__} has no fmi2Functions.h in {where}")
    return where


def host_platform() -> tuple[str, str]:
    """FMI 2.0's name for this machine's binaries folder, and the shared
    library's extension."""
    import fmpy

    extension = _EXTENSIONS.get(sys.platform)
    if extension is None:
        raise GyrogenError(f"FMUs are built on Linux and macOS only, not on {sys.platform}")
    return str(fmpy.platform), extension


def build(model: FmuModel, out: Path) -> dict[str, bytes]:
    """<prefix>.fmu -> its bytes (for files.write_atomic into out's
    directory): the text files, and the binary compiled from them."""
    headers = fmi_headers()
    platform, extension = host_platform()
    texts = fmu.files(model)
    binary = f"binaries/{platform}/{model.prefix}{extension}"
    contents = {name: text.encode() for name, text in texts.items()}
    contents[binary] = _compile(model.prefix, texts, headers)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(contents):
            info = zipfile.ZipInfo(name, _ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name == binary else 0o644) << 16
            zf.writestr(info, contents[name])
    return {f"{model.prefix}.fmu": buffer.getvalue()}


def _compile(prefix: str, texts: dict[str, str], headers: Path) -> bytes:
    """The sources as one shared library (the strict C flags, -Werror
    included, at -O2 without -march=native or OpenMP: portable, like --lib)."""
    gcc = require("gcc")
    with tempfile.TemporaryDirectory(prefix="gyrogen-fmu-") as tmp:
        work = Path(tmp)
        for name, text in texts.items():
            if name.startswith("sources/"):
                (work / Path(name).name).write_text(text)
        sources = sorted(p.name for p in work.glob("*.c"))
        library = work / f"{prefix}.shared"
        cmd = [
            gcc,
            *flags.C_BASE,
            "-O2",
            "-shared",
            f"-I{headers}",
            "-o",
            str(library),
            *sources,
            "-lm",
        ]
        proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            log = cache.cache_dir() / "logs" / f"fmu-{prefix}.log"
            raise cache.failure(f"gcc failed on the FMU of {prefix}", proc.stderr, log)
        return library.read_bytes()
