"""Build step of the mocapd_client package: the protobuf message classes.

Generated code is not committed. Building the package (pip install ./clients/python, from a
checkout) runs protoc --python_out on the checkout's proto/mocap/v1/mocap.proto and puts
mocap/v1/mocap_pb2.py inside the package (mocapd_client/_pb/), where mocapd_client.proto
finds it first. protoc: Debian's protobuf-compiler, or PROTOC=/path/to/protoc.
"""

import os
import shutil
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PROTO_ROOT = HERE.parent.parent / "proto"
PROTO = PROTO_ROOT / "mocap" / "v1" / "mocap.proto"


class BuildWithProto(build_py):
    def run(self):
        super().run()
        protoc = os.environ.get("PROTOC") or shutil.which("protoc")
        if not PROTO.is_file():
            raise SystemExit(f"mocapd_client: {PROTO} not found; build the package from a mocapd checkout")
        if protoc is None:
            raise SystemExit("mocapd_client: protoc not found (Debian: apt install protobuf-compiler, or set PROTOC)")
        out = Path(self.build_lib) / "mocapd_client" / "_pb"
        out.mkdir(parents=True, exist_ok=True)
        subprocess.run([protoc, f"--python_out={out}", f"-I{PROTO_ROOT}", str(PROTO)], check=True)


setup(cmdclass={"build_py": BuildWithProto})
