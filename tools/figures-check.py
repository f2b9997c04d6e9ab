#!/usr/bin/env python3
"""One figure, one place: every figure of docs/figures.toml is read on its owner page, and every
other page that states the same quantity must give the same value.

    tools/figures-check.py [--root DIR]

Prints one line per figure and place; exits 1 on a page that disagrees with the owner, or when a
figure's pattern finds nothing on its owner page (the table has gone stale)."""

import argparse
import re
import sys
import tomllib
from pathlib import Path


def pages(root: Path) -> list[Path]:
    out = [root / "README.md", root / "ARCHITECTURE.md", root / "python" / "README.md"]
    out += sorted(p for p in (root / "docs").rglob("*.md") if "results" not in p.parts)
    return [p for p in out if p.exists()]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    a = ap.parse_args()
    figures = tomllib.loads((a.root / "docs" / "figures.toml").read_text())["figure"]
    broken = 0
    for f in figures:
        owner = a.root / f["owner"]
        m = re.search(f.get("owner_pattern", f["pattern"]), owner.read_text())
        if not m:
            print(f"figure={f['name']!r} owner={f['owner']} value=none: its pattern finds nothing", flush=True)
            broken += 1
            continue
        value = f.get("join", "").join(m.groups()) if f.get("join") else m.group(1)
        print(f"figure={f['name']!r} owner={f['owner']} value={value}")
        for page in pages(a.root):
            if page == owner:
                continue
            for other in re.finditer(f["pattern"], page.read_text()):
                rel = page.relative_to(a.root)
                ok = other.group(1) == value
                broken += not ok
                print(f"  {rel}: {other.group(1)} {'ok' if ok else '!= ' + value}")
    print(f"figures={len(figures)} broken={broken}")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
