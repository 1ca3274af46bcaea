"""``leafsim species`` and ``leafsim params``: the species library and every declared parameter."""

from __future__ import annotations

import json

from leafsim.base.errors import LeafsimError
from leafsim.commands.common import emit
from leafsim.config.params import PARAMS, ParamSet, markdown_table
from leafsim.config.presets import quality_lines, quality_of, quality_table
from leafsim.config.species import load_library


def cmd_species(args):
    rows = [sp.summary() for sp in load_library(args.config).values()]
    lines = [f"{'key':16s} {'name':32s} {'length':>7s}  photo"]
    for r in rows:
        lines.append(f"{r['key']:16s} {r['name']:32s} {r['length_m']:6.3f}m  {r['photo'] or '(drawn outline)'}")
    emit(args, {"species": rows}, "\n".join(lines))


def cmd_params(args):
    if args.markdown and getattr(args, "json", False):
        raise LeafsimError("--markdown and --json: expected one of them (a Markdown table or one JSON object)")
    if args.markdown:
        print(markdown_table())
        return
    rows = [{"name": p.name, "kind": p.kind, "default": p.default, "lo": p.lo, "hi": p.hi, "unit": p.unit,
             "group": p.group, "rebuild": p.rebuild, "choices": list(p.choices), "help": p.help} for p in PARAMS.values()]
    text = "\n".join(f"{r['name']:36s} {str(r['default']):>10s} {r['unit']:10s} {'rebuild' if r['rebuild'] else 'live':7s} {r['help']}" for r in rows)
    quality, default = quality_table(), quality_of(ParamSet())
    text += ("\n\n--quality (measured against each species' converged limit, docs/accuracy.md; the defaults are "
             f"{default}):\n" + "\n".join(f"  {k:10s} {json.dumps(v['settings'])}" for k, v in quality.items())
             + "\n" + "\n".join(f"  {line}" for line in quality_lines(quality, default)))
    emit(args, {"params": rows, "quality": quality}, text)
