"""Assemble README.md from docs/readme/*.md (in name order; 00_intro.md first).

Each section is kept in its own file beside the code it documents; image links inside a
section are relative to docs/readme/ and are rewritten relative to the repository root.
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PARTS = ROOT / "docs" / "readme"
ORDER = ["00_intro.md", "foundation.md", "dynamics.md", "stress.md", "fracture.md", "scenes.md", "usd_blender.md",
         "benchmarks.md"]


def main() -> None:
    names = [n for n in ORDER if (PARTS / n).exists()]
    names += sorted(p.name for p in PARTS.glob("*.md") if p.name not in ORDER)
    chunks = []
    for name in names:
        text = (PARTS / name).read_text().strip() + "\n"
        text = re.sub(r"\]\((?!https?://|/|#)([^)]+\.(?:png|jpg|svg))\)", r"](docs/readme/\1)", text)
        chunks.append(text)
    (ROOT / "README.md").write_text("\n".join(chunks))
    print(f"README.md: {len(names)} sections")


if __name__ == "__main__":
    main()
