"""Write docs/scene_keys.md, the scene-key reference, from mdgran.model.scene.SCHEMA.

    python reference/make_scene_keys.py           # write it
    python reference/make_scene_keys.py --check   # exit 1 if the file is stale

tests/test_material.py runs the check, so the committed file cannot go stale.
"""
from __future__ import annotations

import sys
from pathlib import Path

from mdgran.model.scene import key_reference

OUT = Path(__file__).resolve().parents[1] / "docs" / "scene_keys.md"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = key_reference()
    if "--check" in argv:
        current = OUT.read_text(encoding="utf-8") if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is stale: run python reference/make_scene_keys.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
