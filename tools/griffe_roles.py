"""A griffe extension for the documentation build: Sphinx roles in docstrings as inline code.

The docstrings cite code with reStructuredText roles (``:mod:`piezo_fmu.fmi```, ``:func:`path```);
mkdocstrings renders the docstrings as Markdown, where a role would show as it is written. Each role
becomes the inline code of its target (with ``~``, the target's last component). Used by
``mkdocs.yml`` (the mkdocstrings handler's ``extensions``).
"""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:py:)?(?:mod|func|class|meth|data|attr|exc|obj|const):`(~?)([^`]+)`")


def as_code(match: re.Match) -> str:
    target = match.group(2)
    return f"`{target.rsplit('.', 1)[-1] if match.group(1) else target}`"


class SphinxRolesAsCode(griffe.Extension):
    """Rewrite every docstring's roles as inline code, before mkdocstrings parses it."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(as_code, obj.docstring.value)
