"""The installed message types as a bag holds them: the Python class of a type name, the
ros2msg schema rosbag2 writes, and the RIHS01 type hash (from <prefix>/share/<pkg>/msg/)."""

from __future__ import annotations

import importlib
import json
import os
import re
import sys
from pathlib import Path

PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80


def message_class(type_name: str):
    """'pkg/msg/Type' -> the installed Python message class."""
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _prefixes() -> list[str]:
    found = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return found + [sys.prefix] if sys.prefix not in found else found


def _share_file(pkg: str, name: str, suffix: str) -> Path:
    for prefix in _prefixes():
        path = Path(prefix, "share", pkg, "msg", name + suffix)
        if path.is_file():
            return path
    raise FileNotFoundError(f"{pkg}/msg/{name}{suffix} is not installed under {_prefixes()}")


def _dependencies(pkg: str, text: str) -> list[tuple[str, str]]:
    found = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = re.sub(r"<=\d+$", "", re.sub(r"\[.*\]$", "", line.split()[0]))
        if base in PRIMITIVES:
            continue
        if base == "Header":
            found.append(("std_msgs", "Header"))
        elif "/" in base:
            parts = base.split("/")
            found.append((parts[0], parts[-1]))
        else:
            found.append((pkg, base))
    return found


def schema_text(type_name: str) -> str:
    """The ros2msg schema rosbag2 writes: the .msg text, then every dependency (depth first)."""
    pkg, _, name = type_name.split("/")
    main = _share_file(pkg, name, ".msg").read_text()
    seen, order = {(pkg, name)}, []
    stack = list(reversed(_dependencies(pkg, main)))
    while stack:
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        order.append(dep)
        stack.extend(reversed(_dependencies(dep[0], _share_file(*dep, ".msg").read_text())))
    parts = [main.rstrip("\n")]
    for dep_pkg, dep_name in order:
        parts.append(f"{SEPARATOR}\nMSG: {dep_pkg}/{dep_name}\n"
                     + _share_file(dep_pkg, dep_name, ".msg").read_text().rstrip("\n"))
    return "\n".join(parts) + "\n"


def type_hash(type_name: str) -> str:
    """RIHS01 hash of the type, from the installed <Type>.json (rosbag2's topic_type_hash)."""
    pkg, _, name = type_name.split("/")
    for entry in json.loads(_share_file(pkg, name, ".json").read_text())["type_hashes"]:
        if entry["type_name"] == type_name:
            return entry["hash_string"]
    raise KeyError(f"no type hash for {type_name}")
