#!/usr/bin/env python3
"""layering_check.py — fails when a lower layer of server/ depends on a higher one.

Layers (each a directory of server/; README.md "Layout"):

    core < math < fusion < skeleton; filter and skeleton are siblings (never each other)
    filter, skeleton < pipeline < serve < cluster
    ingest uses core and the wire library only
    serve, cluster and ingest < daemon (which sees everything in server/)
    nothing in server/ includes clients/

Two views of the same rule are checked:
  * every `#include "..."` in server/ and clients/ (a quoted include is resolved next to the
    including file first, then under server/, as the compiler's include path does); an
    include of clients/ from server/ or of a directory that is not a known layer fails too,
    so a new directory must be given its place in ALLOWED below;
  * every target_link_libraries() of a library defined in server/*/CMakeLists.txt: a mocap_*
    library it links must belong to a layer it may include.
Each problem is printed as FILE:LINE: what: rule, and the exit status is 1.

    layering_check.py [ROOT]      check the tree at ROOT (default: this repository)
    layering_check.py --self-test run the checker on small generated trees: a clean one must
                                  pass and each kind of violation must fail, naming file,
                                  line and rule; then check this repository
"""
import os
import re
import sys
import tempfile

SERVER_LAYERS = ["core", "math", "filter", "fusion", "skeleton", "pipeline", "serve", "cluster", "ingest", "daemon"]
# What each layer may include (besides itself). "proto" = headers generated from proto/
# (mocap/v1/*.pb.h), "wire" = the firmware's wire library (mocap_wire/*).
ALLOWED = {
    "core": set(),
    "math": {"core"},
    "filter": {"core", "math"},
    "fusion": {"core", "math"},
    "skeleton": {"core", "math", "fusion"},
    "pipeline": {"core", "math", "filter", "fusion", "skeleton"},
    "serve": {"core", "math", "skeleton", "pipeline", "proto"},
    "cluster": {"core", "math", "skeleton", "pipeline", "serve", "proto"},
    "ingest": {"core", "wire"},
    "daemon": set(SERVER_LAYERS) | {"proto", "wire"},
}
RULES = {
    "core": "core is the bottom layer: it includes nothing else of server/",
    "math": "math sits on core only",
    "filter": "filter sits on core and math; filter and skeleton are siblings and never include each other",
    "fusion": "fusion (the chain stage) sits on core and math; the filters reach it only through frames",
    "skeleton": "skeleton sits on core, math and fusion; filter and skeleton are siblings and never include each other",
    "pipeline": "pipeline sits on core, math, filter, fusion and skeleton; serve and daemon are above it",
    "serve": "serve sits on core, math, skeleton, pipeline and the protobuf headers; not on filter or ingest",
    "cluster": "cluster sits on serve (its frame encoder) and what serve sits on; not on filter or ingest",
    "ingest": "ingest uses core and the wire library (mocap_wire/) only",
    "daemon": "daemon may include anything in server/",
}
# Libraries not defined in server/ whose layer matters; other targets (Eigen, Boost, spdlog,
# Threads, systemd, ...) are third-party and not layered.
EXTERNAL_TARGETS = {"mocap_proto": "proto", "mocap_wire": "wire"}

INCLUDE_RE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')
SOURCE_EXT = (".c", ".h", ".cc", ".cpp", ".hpp", ".in")


def sources(root, top):
    for d, dirs, files in os.walk(os.path.join(root, top)):
        dirs[:] = sorted(x for x in dirs if x not in ("node_modules", "build") and not x.startswith("."))
        for f in sorted(files):
            if f.endswith(SOURCE_EXT):
                yield os.path.join(d, f)


def classify(root, path):
    """(area, layer) of a file: ("server", layer), ("clients", None) or (None, None)."""
    rel = os.path.relpath(path, root).split(os.sep)
    if rel[0] == "server" and len(rel) > 2:
        return "server", rel[1]
    if rel[0] == "clients":
        return "clients", None
    return None, None


def included_layer(root, including, name):
    """The layer an include names: a server layer, "proto", "wire", "clients" or "?name"."""
    local = os.path.normpath(os.path.join(os.path.dirname(including), name))
    if os.path.exists(local):
        area, layer = classify(root, local)
        if area == "server":
            return layer
        if area == "clients":
            return "clients"
    first = name.split("/")[0]
    if first == "mocap":
        return "proto"
    if first == "mocap_wire":
        return "wire"
    if first == "clients":
        return "clients"
    if "/" in name:
        return first if first in ALLOWED else "?" + first
    return "?" + name


def check_includes(root, problems):
    for top in ("server", "clients"):
        for path in sources(root, top):
            area, layer = classify(root, path)
            rel = os.path.relpath(path, root)
            with open(path, encoding="utf-8", errors="replace") as f:
                for n, line in enumerate(f, 1):
                    m = INCLUDE_RE.match(line)
                    if not m:
                        continue
                    target = included_layer(root, path, m.group(1))
                    if area == "clients":
                        continue  # clients sit above everything; only server/ is layered
                    where = f'{rel}:{n}: {layer}/ includes "{m.group(1)}"'
                    if layer not in ALLOWED:
                        problems.append(f"{where}: server/{layer}/ is not a known layer (give it a place in "
                                        f"tests/static/layering_check.py)")
                    elif target == "clients":
                        problems.append(f"{where}: nothing in server/ includes clients/")
                    elif target.startswith("?"):
                        problems.append(f"{where}: {target[1:]} is neither a layer of server/ nor a generated "
                                        f"or wire header")
                    elif target != layer and target not in ALLOWED[layer]:
                        problems.append(f"{where} ({target}): {RULES[layer]}")


def cmake_commands(text, command):
    """(line, [words]) of each call of `command` in a CMakeLists text."""
    for m in re.finditer(r"\b" + command + r"\s*\(([^)]*)\)", text):
        body = re.sub(r"#[^\n]*", "", m.group(1))
        yield text.count("\n", 0, m.start()) + 1, body.split()


def check_links(root, problems):
    layer_of = dict(EXTERNAL_TARGETS)
    files = {}
    for layer in sorted(os.listdir(os.path.join(root, "server"))):
        path = os.path.join(root, "server", layer, "CMakeLists.txt")
        if not os.path.isfile(path):
            continue
        with open(path, encoding="utf-8") as f:
            files[layer] = (os.path.relpath(path, root), f.read())
        for _, words in cmake_commands(files[layer][1], "add_library"):
            if words:
                layer_of[words[0]] = layer
    for layer, (rel, text) in files.items():
        for line, words in cmake_commands(text, "target_link_libraries"):
            if not words or layer_of.get(words[0]) != layer:
                continue
            for dep in words[1:]:
                dep_layer = layer_of.get(dep)
                if dep_layer is None or dep_layer == layer:
                    continue  # third-party, or a library of the same layer
                if layer not in ALLOWED:
                    problems.append(f"{rel}:{line}: {words[0]} links {dep}: server/{layer}/ is not a known layer")
                elif dep_layer not in ALLOWED[layer]:
                    problems.append(f"{rel}:{line}: {words[0]} links {dep} ({dep_layer}): {RULES[layer]}")


def check(root):
    problems = []
    check_includes(root, problems)
    check_links(root, problems)
    return problems


def write(root, rel, text):
    path = os.path.join(root, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def self_test():
    """Each case: files added to a clean tree, and the text every problem report must hold
    (None: the tree must pass)."""
    clean = {
        "server/core/CMakeLists.txt": "add_library(mocap_core STATIC a.cpp)\n",
        "server/core/a.hpp": "#pragma once\n",
        "server/math/CMakeLists.txt": "add_library(mocap_math STATIC q.cpp)\n"
                                      "target_link_libraries(mocap_math PUBLIC mocap_core Eigen3::Eigen)\n",
        "server/math/q.hpp": '#include "core/a.hpp"\n',
        "server/filter/CMakeLists.txt": "add_library(mocap_filter STATIC f.cpp)\n"
                                        "target_link_libraries(mocap_filter PUBLIC mocap_math)\n",
        "server/filter/f.cpp": '#include "filter/f.hpp"\n#include "math/q.hpp"\n#include "f_local.hpp"\n',
        "server/filter/f.hpp": "#pragma once\n",
        "server/filter/f_local.hpp": "#pragma once\n",
        "server/skeleton/s.hpp": '#include "math/q.hpp"\n',
        "server/ingest/i.cpp": '#include "core/a.hpp"\n#include "mocap_wire/mw_can.h"\n',
        "server/serve/v.cpp": '#include "skeleton/s.hpp"\n#include "mocap/v1/mocap.pb.h"\n',
        "server/daemon/d.cpp": '#include "serve/v.hpp"\n#include "ingest/i.hpp"\n#include "filter/f.hpp"\n',
        "clients/tool/t.cpp": '#include "daemon/d.hpp"\n#include "t_local.hpp"\n',
        "clients/tool/t_local.hpp": "#pragma once\n",
    }
    cases = [
        ("clean", {}, None),
        ("lower includes higher", {"server/core/b.cpp": '// x\n#include "filter/f.hpp"\n'},
         'server/core/b.cpp:2: core/ includes "filter/f.hpp" (filter): core is the bottom layer'),
        ("siblings", {"server/skeleton/t.cpp": '#include "filter/f.hpp"\n'},
         "server/skeleton/t.cpp:1: skeleton/ includes \"filter/f.hpp\" (filter): skeleton sits on core, math and fusion; "
         "filter and skeleton are siblings"),
        ("ingest beyond core and wire", {"server/ingest/j.cpp": '#include "math/q.hpp"\n'},
         "server/ingest/j.cpp:1: ingest/ includes \"math/q.hpp\" (math): ingest uses core and the wire library"),
        ("serve includes filter", {"server/serve/w.cpp": '#include "filter/f.hpp"\n'},
         "server/serve/w.cpp:1: serve/ includes \"filter/f.hpp\" (filter): serve sits on"),
        ("server includes clients", {"server/daemon/e.cpp": '#include "../../clients/tool/t_local.hpp"\n'},
         'server/daemon/e.cpp:1: daemon/ includes "../../clients/tool/t_local.hpp": nothing in server/ '
         "includes clients/"),
        ("unknown layer", {"server/extra/x.cpp": '#include "core/a.hpp"\n'},
         "server/extra/x.cpp:1: extra/ includes \"core/a.hpp\": server/extra/ is not a known layer"),
        ("link against a higher layer", {"server/math/CMakeLists.txt": "add_library(mocap_math STATIC q.cpp)\n"
                                         "target_link_libraries(mocap_math\n  PUBLIC mocap_core mocap_filter)\n"},
         "server/math/CMakeLists.txt:2: mocap_math links mocap_filter (filter): math sits on core only"),
    ]
    failed = 0
    for name, extra, expect in cases:
        with tempfile.TemporaryDirectory() as root:
            for rel, text in {**clean, **extra}.items():
                write(root, rel, text)
            problems = check(root)
        ok = (not problems) if expect is None else (len(problems) == 1 and problems[0].startswith(expect))
        print(f"self-test {name}: {'ok' if ok else 'FAILED'}")
        if not ok:
            failed += 1
            print(f"  expected: {expect or 'no problem'}")
            for p in problems:
                print(f"  got: {p}")
    return failed == 0


def main(argv):
    here = os.path.dirname(os.path.abspath(__file__))
    args = argv[1:]
    if args and args[0] == "--self-test":
        if not self_test():
            print("layering_check: the checker's self-test failed")
            return 1
        args = args[1:]
    root = os.path.abspath(args[0]) if args else os.path.normpath(os.path.join(here, "..", ".."))
    problems = check(root)
    for p in problems:
        print(p)
    if problems:
        print(f"layering_check: {len(problems)} dependency(ies) against the layering (docstring of {__file__})")
        return 1
    print("layering_check: every include and link of server/ follows the layering")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
