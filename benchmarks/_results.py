"""Where every benchmark writes its results: NAME.md (the table the README quotes) and
NAME.json (the figures) under the output directory, and the table on stdout."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_results(out: str | Path, name: str, lines: list[str], data: Any) -> None:
    directory = Path(out)
    directory.mkdir(parents=True, exist_ok=True)
    (directory / f"{name}.md").write_text("\n".join(lines) + "\n")
    (directory / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
    print("\n".join(lines))
