"""The docs tables' shared formatting: reading a results file, a Markdown table, significant
digits, the provenance line."""

import json


def _read(docs, name):
    """The results file ``docs/name``, parsed."""
    return json.loads((docs / name).read_text())


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def _sig(x, digits=3):
    return f"{x:.{digits}g}"


def _power_of_ten(n):
    exponent = len(str(n)) - 1
    superscript = str(exponent).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"10{superscript}" if n == 10**exponent else str(n)


def _load_note(machine):
    """How busy the machine was, where benchmarks/regenerate.py recorded it (``machine["load"]``)."""
    load = machine.get("load")
    if not load or load.get("other_cores") is None:
        return ""
    if load.get("quiet"):
        return f", quiet cores (others {load['other_cores']:.2f} cores)"
    return f", **under load** (others {load['other_cores']:.2f} cores: its timings are not the figure)"


def _provenance(name, machine, context=""):
    """The italic line under a table from a schema-2 results file: where, on what, from which commit,
    and how busy the machine was when that was recorded."""
    m = machine
    return (
        f"\n\n*From `docs/{name}`{context}: {m['cpus']} CPU cores, Python {m['python']}, "
        f"jax {m['jax']}, diffrax {m['diffrax']}, commit {m['commit']}, {m['date']}{_load_note(m)}.*"
    )
