"""Read the ROS 2 XML launch files of this package without the launch packages.

``ros2 launch`` is the way to run the suite on a robot; where the launch packages are not
installable (PyPI has none) the system test and ``make demo`` start the very processes the
launch file declares, from this parser, so the two cannot drift. Supported subset (what our
launch files use): ``<arg name default>``, ``<node pkg exec name namespace>`` with ``<param
from>``, ``<param name value>`` and ``<remap from to>`` children, ``<set_env name value>``
(applies to the nodes after it, included files too, as in ``ros2 launch``), ``<include file>``
with ``<arg name value>`` children, and the substitutions ``$(var NAME)`` and
``$(find-pkg-share PKG)``. Anything else raises ``ValueError`` rather than being silently ignored.
"""

from __future__ import annotations

import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import yaml

_SUBSTITUTION = re.compile(r"\$\(([a-z-]+)\s+([^)]*)\)")


@dataclass
class NodeLaunch:
    """One node of a launch file, fully resolved."""

    package: str
    executable: str
    name: str
    namespace: str = ""
    parameters: list = field(default_factory=list)  # Path (params file) or (name, value str)
    remappings: list[tuple[str, str]] = field(default_factory=list)
    environment: dict[str, str] = field(default_factory=dict)  # from <set_env> before the node

    @property
    def full_name(self) -> str:
        return "/".join(["", *filter(None, self.namespace.strip("/").split("/")), self.name])

    def command(
        self, scripts_dir: Path, params_dir: Path, python: str = sys.executable
    ) -> list[str]:
        """argv that runs this node from the package's ``scripts/`` directory.

        As ``ros2 launch`` does, each run of ``<param name value>`` entries is written to a
        parameter file keyed by the node's full name in ``params_dir`` (values parsed as YAML),
        so it overrides the node's section of an earlier file (a bare ``-p`` would not: rcl
        prefers node-specific entries to wildcard ones).
        """
        argv = [python, str(scripts_dir / self.executable), "--ros-args"]
        argv += ["-r", f"__node:={self.name}"]
        if self.namespace:
            argv += ["-r", f"__ns:={self.namespace}"]
        for index, group in enumerate(self._parameter_groups()):
            if isinstance(group, Path):
                argv += ["--params-file", str(group)]
                continue
            values = {k: yaml.safe_load(v) if v != "" else "" for k, v in group}
            path = Path(params_dir) / f"{self.full_name.strip('/').replace('/', '__')}_{index}.yaml"
            path.write_text(yaml.safe_dump({self.full_name: {"ros__parameters": values}}))
            argv += ["--params-file", str(path)]
        for source, target in self.remappings:
            argv += ["-r", f"{source}:={target}"]
        return argv

    def _parameter_groups(self) -> list:
        """Files as they are, consecutive name/value pairs grouped into lists."""
        groups: list = []
        for item in self.parameters:
            if isinstance(item, Path):
                groups.append(item)
            elif groups and isinstance(groups[-1], list):
                groups[-1].append(item)
            else:
                groups.append([item])
        return groups

    def parameter_files(self) -> list[Path]:
        return [p for p in self.parameters if isinstance(p, Path)]

    def parameter_values(self) -> dict[str, str]:
        return dict(p for p in self.parameters if not isinstance(p, Path))


def _substitute(text: str, args: dict[str, str], share_dirs: dict[str, Path]) -> str:
    def replace(match: re.Match) -> str:
        kind, value = match.group(1), match.group(2).strip()
        if kind == "var":
            if value not in args:
                raise ValueError(f"launch argument {value!r} is not declared")
            return args[value]
        if kind == "find-pkg-share":
            if value not in share_dirs:
                raise ValueError(f"unknown package {value!r} in $(find-pkg-share)")
            return str(share_dirs[value])
        raise ValueError(f"unsupported substitution $({kind} ...)")

    return _SUBSTITUTION.sub(replace, text)


def parse(
    path: Path,
    share_dirs: dict[str, Path],
    arguments: dict[str, str] | None = None,
    environment: dict[str, str] | None = None,
) -> list[NodeLaunch]:
    """Nodes of the launch file at ``path`` with launch ``arguments`` (``name:=value`` pairs).

    ``share_dirs`` maps package names to their share directory (the source tree works: it holds
    ``launch/`` and ``config/``); ``environment`` holds variables set by an including file.
    """
    root = ET.parse(path).getroot()
    if root.tag != "launch":
        raise ValueError(f"{path}: root element must be <launch>")
    given = dict(arguments or {})
    args: dict[str, str] = {}
    nodes: list[NodeLaunch] = []
    env = dict(environment or {})

    def sub(text: str) -> str:
        return _substitute(text, args, share_dirs)

    for element in root:
        if element.tag == "arg":
            name = element.attrib["name"]
            if name in given:
                args[name] = given.pop(name)
            elif "default" in element.attrib:
                args[name] = sub(element.attrib["default"])
            else:
                raise ValueError(f"{path}: launch argument {name!r} has no value")
        elif element.tag == "set_env":
            env[element.attrib["name"]] = sub(element.attrib["value"])
        elif element.tag == "node":
            nodes.append(_node(element, sub, env))
        elif element.tag == "include":
            child_args = {a.attrib["name"]: sub(a.attrib["value"]) for a in element.iter("arg")}
            nodes += parse(Path(sub(element.attrib["file"])), share_dirs, child_args, env)
        else:
            raise ValueError(f"{path}: unsupported launch element <{element.tag}>")
    if given:
        raise ValueError(f"{path}: unknown launch arguments {sorted(given)}")
    return nodes


def _node(element: ET.Element, sub, environment: dict[str, str]) -> NodeLaunch:
    node = NodeLaunch(
        package=element.attrib["pkg"],
        executable=element.attrib["exec"],
        name=element.attrib["name"],
        namespace=element.attrib.get("namespace", ""),
        environment=dict(environment),
    )
    for child in element:
        if child.tag == "param" and "from" in child.attrib:
            node.parameters.append(Path(sub(child.attrib["from"])))
        elif child.tag == "param":
            node.parameters.append((child.attrib["name"], sub(child.attrib["value"])))
        elif child.tag == "remap":
            node.remappings.append((sub(child.attrib["from"]), sub(child.attrib["to"])))
        else:
            raise ValueError(f"unsupported <{child.tag}> inside <node>")
    return node
