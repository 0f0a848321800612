"""Finds the classes generated from proto/mocap/v1/mocap.proto (mocap_pb2).

Generated code is not committed; it is looked up in this order:

1. ``MOCAPD_CLIENT_PB2_DIR``: a ``protoc --python_out`` directory that holds
   ``mocap/v1/mocap_pb2.py``. The CMake build writes one to
   ``<build>/clients/python/generated`` (target ``mocapd_client_py``).
2. The copy inside the package, ``mocapd_client/_pb/``, which an installed package has
   (``pip install ./clients/python`` generates it: setup.py).
3. An importable ``mocap.v1.mocap_pb2`` (a generated tree already on ``sys.path``).
4. When this package runs from a source checkout and ``protoc`` is on PATH: generated now
   from the checkout's ``proto/`` into ``$XDG_CACHE_HOME/mocapd_client/<hash>/`` (the hash
   of the .proto text, so an edited .proto is regenerated).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from types import ModuleType

PB2_DIR_ENV = "MOCAPD_CLIENT_PB2_DIR"
_RELATIVE = Path("mocap") / "v1" / "mocap_pb2.py"
_PROTO_ROOT = Path(__file__).resolve().parents[3] / "proto"
_INSTALLED = Path(__file__).resolve().parent / "_pb"


class ProtoNotFound(ImportError):
    """No generated mocap_pb2 and no way to generate one."""


def _load_file(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location("mocapd_client._mocap_pb2", path)
    if spec is None or spec.loader is None:
        raise ProtoNotFound(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _generate_from_checkout() -> Path | None:
    source = _PROTO_ROOT / "mocap" / "v1" / "mocap.proto"
    protoc = shutil.which("protoc")
    if not source.is_file() or protoc is None:
        return None
    digest = hashlib.sha256(source.read_bytes()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mocapd_client" / digest
    if (cache / _RELATIVE).is_file():
        return cache
    cache.parent.mkdir(parents=True, exist_ok=True)
    # Generate into a fresh directory and rename it into place, so concurrent first runs
    # never see a half-written module.
    tmp = Path(tempfile.mkdtemp(prefix=".gen-", dir=cache.parent))
    try:
        subprocess.run([protoc, f"--python_out={tmp}", f"-I{_PROTO_ROOT}", str(source)], check=True,
                       capture_output=True)
        try:
            tmp.rename(cache)
        except OSError:  # another process won the race; its copy is identical
            pass
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return cache if (cache / _RELATIVE).is_file() else None


def load_mocap_pb2() -> ModuleType:
    configured = os.environ.get(PB2_DIR_ENV)
    if configured:
        path = Path(configured) / _RELATIVE
        if not path.is_file():
            raise ProtoNotFound(f"{PB2_DIR_ENV}={configured} holds no {_RELATIVE}")
        return _load_file(path)
    if (_INSTALLED / _RELATIVE).is_file():
        return _load_file(_INSTALLED / _RELATIVE)
    try:
        return importlib.import_module("mocap.v1.mocap_pb2")
    except ImportError:
        pass
    generated = _generate_from_checkout()
    if generated is None:
        raise ProtoNotFound(
            f"mocap_pb2 not found: set {PB2_DIR_ENV} to a protoc --python_out directory "
            "(the build writes <build>/clients/python/generated), or install protoc")
    return _load_file(generated / _RELATIVE)


pb = load_mocap_pb2()
