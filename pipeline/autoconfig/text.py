"""The commented YAML text of a drafted flight config: each key under the paragraphs that say where its value came
from, the placeholders commented out where they belong, marked FILL IN."""

from __future__ import annotations

import textwrap

import yaml

from pipeline.autoconfig.draft import Draft

KEY_ORDER = ("name", "files", "mapping", "altitude", "camera", "lever_arms_m", "clock", "target", "observations",
             "sigma", "terrain", "marks_file")
WIDTH = 112
FLOW_MAX = 100  # a value whose flow form is longer is written as a block


def _flow(value) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6, sort_keys=False)
    return text.removesuffix("\n...\n").strip()


def _comment(paragraph: str, indent: str = "") -> list[str]:
    return [f"{indent}# {line}" for line in textwrap.wrap(paragraph, width=WIDTH - 2 - len(indent))]


def _value_lines(key: str, value, block: bool = False) -> list[str]:
    flow = _flow(value)
    if not isinstance(value, dict) or (len(key) + len(flow) + 2 <= FLOW_MAX and not block):
        return [f"{key}: {flow}"]
    lines = [f"{key}:"]
    for k, v in value.items():
        if isinstance(v, list) and v and all(isinstance(row, list) for row in v):  # a matrix: one row a line
            lines += [f"  {k}:", *(f"  - {_flow(row)}" for row in v)]
        else:
            lines.append(f"  {k}: {_flow(v)}")
    return lines


def config_text(draft: Draft, command: str) -> str:
    """The config's text; `command` the command line that wrote it, for the header. The text parses back to
    `draft.doc` exactly (the comments change no value)."""
    lines = _comment(
        f"Written by `{command}` from the files of the flight: every value below is what a file states or what "
        "the data show, with where it came from above it. Lines marked FILL IN are facts no file states: "
        "uncomment them and fill them in. docs/flight_config.md explains every key.")
    keys = list(KEY_ORDER) + [k for k in draft.doc if k not in KEY_ORDER]
    for key in keys:
        paragraphs = draft.comments.get(key, [])
        placeholders = [f for f in draft.fill_in if f.key == key]
        if not (paragraphs or placeholders or key in draft.doc):
            continue
        for p in paragraphs:
            lines += _comment(p)
        if key not in draft.doc:
            for f in placeholders:
                lines += [f"# {line}" for line in f.lines]
            continue
        lines += _value_lines(key, draft.doc[key], block=bool(placeholders))
        for f in placeholders:  # more keys of the same section: commented inside its block
            why = f.lines[0].partition("#")[2]
            lines += [f"  # {why.strip()}"] if why else []
            lines += [f"  # {line.strip()}" for line in f.lines[1:]]
    text = "\n".join(lines) + "\n"
    if yaml.safe_load(text) != draft.doc:  # the layout must not change any value
        raise AssertionError("the drafted config's text does not parse back to its values")
    return text
