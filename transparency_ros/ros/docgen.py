"""The generated parts of the docs and config files, from the code's own tables.

* the parameter table of each node (its ``ParamSpec`` rows) in ``docs/<node>.md``;
* ``config/<node>.yaml``, every parameter with its default (usable with ``--params-file``);
* the subcommand table of the ``transparency`` command (its argparse parser) in ``docs/cli.md``.

A generated block sits between ``<!-- generated: NAME -->`` and ``<!-- end generated: NAME -->``.
``python -m transparency_ros.ros.docgen`` (``make docs``) rewrites them; with ``--check`` it
only lists what is stale and exits 1. ``test/ros/test_docs.py`` runs the check, so the docs
cannot drift from the code.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from transparency_ros.ros.params import ParamSpec

ROOT = Path(__file__).resolve().parents[2]


def _default_text(value: object) -> str:
    if isinstance(value, str):
        return f"`{value}`" if value else "`''`"
    if isinstance(value, list):
        return "`" + json.dumps(value) + "`"
    return f"{value!r}"


def _range_text(spec: ParamSpec) -> str:
    if spec.choices:
        return " (" + " / ".join(spec.choices) + ")"
    if spec.low is not None and spec.high is not None:
        return f" [{spec.low:g}, {spec.high:g}]"
    return ""


def parameter_table(specs: Sequence[ParamSpec]) -> str:
    """Markdown: name, default, whether it can change at runtime, meaning with range."""
    rows = [
        "| parameter | default | runtime | meaning |",
        "|---|---|---|---|",
    ]
    for s in specs:
        runtime = "no" if s.read_only else "yes"
        meaning = (s.description + _range_text(s)).replace("|", "\\|")
        rows.append(f"| `{s.name}` | {_default_text(s.default)} | {runtime} | {meaning} |")
    return "\n".join(rows) + "\n"


def _yaml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (str, list)):
        return json.dumps(value)
    return repr(value)


def params_file(node: str, specs: Sequence[ParamSpec]) -> str:
    """config/<node>.yaml: every parameter with its default and (shortened) description."""
    lines = [
        f"# Parameters of {node} with their defaults. Generated from the node's parameter table",
        "# by `make docs` (python -m transparency_ros.ros.docgen); test/ros/test_docs.py keeps",
        "# this file equal to it.",
        f"# Use: ros2 run transparency_ros {node} --ros-args --params-file <this file>",
        f"{node}:",
        "  ros__parameters:",
    ]
    for s in specs:
        line = f"    {s.name}: {_yaml_value(s.default)}  # {s.description}"
        if len(line) > 100:  # a comment that fits; --help and the docs have it whole
            line = line[:96].rsplit(" ", 1)[0] + " ..."
        lines.append(line)
    return "\n".join(lines) + "\n"


def subcommand_table() -> str:
    """Markdown: every ``transparency`` subcommand with its one-line help."""
    from transparency_ros.cli import build_parser  # noqa: PLC0415

    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    rows = ["| subcommand | what it does |", "|---|---|"]
    for choice in action._choices_actions:
        rows.append(f"| `{choice.dest}` | {choice.help} |")
    return "\n".join(rows) + "\n"


def _node_tables() -> dict[str, Callable[[], Sequence[ParamSpec]]]:
    from transparency_ros.ros import (  # noqa: PLC0415
        actuator_driver,
        estimator_params,
        feel_cage_behavior,
    )

    return {
        "actuator_driver": lambda: actuator_driver.PARAMETERS,
        "contact_estimator": lambda: estimator_params.PARAMETERS,
        "feel_cage_behavior": feel_cage_behavior.parameters,
    }


def blocks() -> dict[Path, dict[str, str]]:
    """{docs page: {block name: generated text}}."""
    out: dict[Path, dict[str, str]] = {}
    for node, specs in _node_tables().items():
        out.setdefault(ROOT / "docs" / f"{node}.md", {})[f"{node} parameters"] = parameter_table(
            specs()
        )
    out.setdefault(ROOT / "docs" / "cli.md", {})["subcommands"] = subcommand_table()
    out.setdefault(ROOT / "docs" / "feel_cage.md", {})["feelcage core"] = feelcage_core_table()
    return out


def feelcage_core_table() -> str:
    """What `transparency feelcage --engine core` prints (deterministic: the cores in one
    process), so the page's table is the code's."""
    import contextlib  # noqa: PLC0415
    import io  # noqa: PLC0415

    from transparency_ros.cli import main as cli  # noqa: PLC0415

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        cli(["feelcage", "--engine", "core"])
    return "```\n" + out.getvalue().rstrip("\n") + "\n```\n"


def files() -> dict[Path, str]:
    """Whole generated files: config/<node>.yaml, config/feel_cage_nodes.yaml."""
    out = {
        ROOT / "config" / f"{node}.yaml": params_file(node, specs())
        for node, specs in _node_tables().items()
    }
    out[ROOT / "config" / "feel_cage_nodes.yaml"] = feel_cage_nodes_file()
    return out


def feel_cage_nodes_file() -> str:
    """The feel-cage task's three nodes, as ``transparency feelcage --engine ros`` starts them
    (U10DD, rubber ball): one --params-file for all three."""
    from transparency_ros.core.feel_cage_config import load_setup  # noqa: PLC0415
    from transparency_ros.ros.feelcage_run import node_parameters  # noqa: PLC0415

    lines = [
        "# The feel-cage task's nodes as `transparency feelcage --engine ros` starts them (U10DD,",
        "# rubber ball; see docs/feel_cage.md, 'The nodes by hand'). Generated by `make docs`",
        "# from ros/feelcage_run.py; test/ros/test_docs.py keeps this file equal to it. Use:",
        "#   ros2 run transparency_ros <node> --ros-args --params-file config/feel_cage_nodes.yaml",
    ]
    for node, values in node_parameters("U10DD", "rubber", load_setup()).items():
        lines += [f"{node}:", "  ros__parameters:"]
        lines += [f"    {k}: {_yaml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def _pattern(name: str) -> re.Pattern[str]:
    n = re.escape(name)
    return re.compile(rf"(<!-- generated: {n} -->\n)(.*?)(<!-- end generated: {n} -->)", re.S)


def render(text: str, page: Path, generated: dict[str, str]) -> str:
    """``text`` with each named block replaced by its generated content."""
    for name, body in generated.items():
        pattern = _pattern(name)
        if not pattern.search(text):
            raise ValueError(f"{page}: no block '<!-- generated: {name} -->' to fill")

        def fill(m: re.Match[str], body: str = body) -> str:
            return m.group(1) + body + m.group(3)

        text = pattern.sub(fill, text)
    return text


def stale() -> list[Path]:
    """Files whose generated parts differ from what the code gives now."""
    out = [path for path, text in files().items() if not path.is_file() or path.read_text() != text]
    for page, generated in blocks().items():
        text = page.read_text()
        if render(text, page, generated) != text:
            out.append(page)
    return out


def write() -> list[Path]:
    """Rewrite what is stale; return what was written."""
    written = []
    for path, text in files().items():
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
            written.append(path)
    for page, generated in blocks().items():
        text = page.read_text()
        new = render(text, page, generated)
        if new != text:
            page.write_text(new)
            written.append(page)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m transparency_ros.ros.docgen",
        description="Regenerate the parameter tables, config/<node>.yaml and the subcommand "
        "table from the code (a source checkout).",
    )
    parser.add_argument("--check", action="store_true", help="list stale files, exit 1 if any")
    args = parser.parse_args(argv)
    if args.check:
        old = stale()
        for path in old:
            print(f"stale: {path.relative_to(ROOT)} (run make docs)")  # noqa: T201
        return 1 if old else 0
    for path in write():
        print(f"wrote {path.relative_to(ROOT)}")  # noqa: T201
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
