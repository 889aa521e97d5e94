"""Griffe extension: read a Google-style ``Example:`` section as ``Examples:``.

jaxrot's docstrings title their doctests ``Example:``, which griffe's Google parser takes
for an admonition, so the ``>>>`` lines would reach Markdown as nested block quotes. Renamed
before parsing, they become an examples section that mkdocstrings renders as highlighted
``pycon`` code, prompts and outputs as written (and run by ``pytest --doctest-modules``).
"""

import re

import griffe


_EXAMPLE = re.compile(r"^(\s*)Example:[ \t]*$", re.MULTILINE)


class ExampleSections(griffe.Extension):
    """Rename ``Example:`` section titles to ``Examples:`` in every docstring griffe loads."""

    def on_instance(self, *, node, obj, agent, **kwargs):
        if obj.docstring is not None:
            obj.docstring.value = _EXAMPLE.sub(r"\1Examples:", obj.docstring.value)
