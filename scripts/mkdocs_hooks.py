"""MkDocs hooks of the documentation site (mkdocs.yml ``hooks:``): pages generated from the
code at build time, so they cannot drift from it.

- ``<!-- scene-file-reference -->`` becomes every scene-file key's table
  (``taichi_frac.scenes.reference``: defaults, units, ranges and meanings read from the
  option dataclasses); a key without a docstring entry fails the strict build.
- ``<!-- cli-reference -->`` becomes the ``--help`` of every ``taichi-frac`` command.
"""

from __future__ import annotations

import argparse
import logging
import os

log = logging.getLogger("mkdocs.plugins.taichi_frac")

SCENE_MARKER = "<!-- scene-file-reference -->"
CLI_MARKER = "<!-- cli-reference -->"


def _cli_reference() -> str:
    from taichi_frac.cli import build_parser

    os.environ.setdefault("COLUMNS", "100")  # argparse wraps help to the terminal width
    parser = build_parser()
    parts = ["```text", parser.format_help().rstrip(), "```", ""]
    for action in parser._actions:
        if not isinstance(action, argparse._SubParsersAction):
            continue
        for name, sub in action.choices.items():
            parts += [f"## `taichi-frac {name}`", "", "```text", sub.format_help().rstrip(), "```", ""]
            for inner in sub._actions:  # (bench's targets)
                if isinstance(inner, argparse._SubParsersAction):
                    for target, target_parser in inner.choices.items():
                        parts += [f"### `taichi-frac {name} {target}`", "", "```text",
                                  target_parser.format_help().rstrip(), "```", ""]
    return "\n".join(parts)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if SCENE_MARKER in markdown:
        from taichi_frac.scenes.reference import scene_file_reference, undocumented_keys

        for key in undocumented_keys():
            log.warning(f"scene-file key without a docstring entry (add it to the class's Attributes): {key}")
        markdown = markdown.replace(SCENE_MARKER, scene_file_reference())
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, _cli_reference())
    return markdown
