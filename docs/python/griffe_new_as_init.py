"""A griffe extension for the documentation site (mkdocs.yml): pyo3 classes as stubs declare them.

The extension's classes are pyo3 classes whose constructor is `__new__` (the type stubs must
say so for mypy.stubtest), while mkdocstrings merges only an `__init__` into the class's
heading and checks a class docstring's ``Args:`` against `__init__`'s parameters. This
extension presents every `__new__` of a class without an `__init__` as that `__init__`
(``cls`` becomes ``self``), so that the constructor's signature and arguments are documented
with the class.

It also gives a method that a stub declares only as ``@overload`` variants (a stub has no
implementation) a documented entry: griffe otherwise drops such a method. The entry takes the
first variant's signature and docstring, and lists every variant as its overloads.

Docstring warnings stay on for the extension's stubs (the strict build fails on them), and are
off under ``fuzzyq.envs``, whose free-form sections (``Semantics:``, a ``Raises:`` line that
refers to another class) are not Google-style items; those modules' own tests check them.
"""

from __future__ import annotations

from typing import Any

import griffe


class NewAsInit(griffe.Extension):
    """Renames each class's `__new__` to `__init__`; documents stub-only overloaded methods."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        """Called by griffe for every object: silences docstring warnings under fuzzyq.envs."""
        if obj.docstring is not None and obj.path.startswith("fuzzyq.envs"):
            obj.docstring.parser_options = {**obj.docstring.parser_options, "warnings": False}

    def on_class_members(self, *, cls: griffe.Class, **kwargs: Any) -> None:
        """Called by griffe once the members of `cls` are loaded."""
        for name, variants in list(cls.overloads.items()):
            if not variants or name in cls.members:
                continue
            first = variants[0]
            entry = griffe.Function(
                name,
                lineno=first.lineno,
                endlineno=first.endlineno,
                parameters=first.parameters,
                returns=first.returns,
                decorators=[],
                docstring=first.docstring,
                parent=cls,
                analysis="static",
            )
            entry.overloads = list(variants)
            cls.set_member(name, entry)
            del cls.overloads[name]
        new = cls.members.get("__new__")
        if new is None or "__init__" in cls.members or not isinstance(new, griffe.Function):
            return
        cls.del_member("__new__")
        new.name = "__init__"
        params = list(new.parameters)
        if params and params[0].name == "cls":
            params[0] = griffe.Parameter("self", kind=params[0].kind)
            new.parameters = griffe.Parameters(*params)
        new.returns = "None"
        new.docstring = None  # the class docstring documents the constructor
        cls.set_member("__init__", new)
