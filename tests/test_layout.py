"""How wide texcook's functions may be.

The rule, checked over every .py file under texcook/:

- A function (def, async def, method, nested function or lambda) takes at
  most 12 parameters. Every parameter counts one: positional, keyword-only,
  `*args` and `**kwargs` alike. Values that belong together travel together:
  a frozen dataclass or the plan/recipe object in Python, a tuple or a
  record in a kernel.
- The one exception is a numba kernel (decorated with texcook._jit's `jit`,
  `jit_inner` or `jit_typed`, with or without options) that takes exactly one
  table record and exactly one scratch record plus the block data: the two
  records do not count, the block data (every other parameter) is held to
  the same 12. A table record is the per-call constants as one value (a
  preset row from PresetTable.record, a per-size BlockTables, a structured
  array of settings) and is named `rec`, `tab` or `prm`; a scratch record is
  one thread's working arrays as one tuple or named tuple, named `ws` or
  `scratch`. So a kernel never takes more than 14, and only in that shape.
"""

import ast
import pathlib
import textwrap

import pytest

LIMIT = 12
TABLE_RECORDS = frozenset({"rec", "tab", "prm"})
SCRATCH_RECORDS = frozenset({"ws", "scratch"})
KERNEL_DECORATORS = frozenset({"jit", "jit_inner", "jit_typed"})
ROOT = pathlib.Path(__file__).resolve().parent.parent / "texcook"


def _names(args):
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return names


def _is_kernel(node):
    for dec in getattr(node, "decorator_list", ()):
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", None)
        if name in KERNEL_DECORATORS:
            return True
    return False


def follows_record_rule(node):
    """True for a kernel taking one table record, one scratch record and at
    most LIMIT further parameters."""
    names = _names(node.args)
    tables = [n for n in names if n in TABLE_RECORDS]
    scratch = [n for n in names if n in SCRATCH_RECORDS]
    return (_is_kernel(node) and len(tables) == 1 and len(scratch) == 1
            and len(names) - 2 <= LIMIT)


def too_wide(source, filename="<source>"):
    """[(line, name, parameter count)] of the functions in `source` that break the rule."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        count = len(_names(node.args))
        if count > LIMIT and not follows_record_rule(node):
            found.append((node.lineno, getattr(node, "name", "<lambda>"), count))
    return found


def test_no_function_in_texcook_takes_more_than_12_parameters():
    files = sorted(ROOT.rglob("*.py"))
    assert len(files) > 20  # the walk found the package
    wide = [f"{path.relative_to(ROOT.parent)}:{line} {name} takes {count}"
            for path in files for line, name, count in too_wide(path.read_text(encoding="utf-8"), str(path))]
    assert not wide, "over 12 parameters (see this file's docstring for the rule):\n" + "\n".join(wide)


def _params(n, *named):
    return ", ".join(list(named) + [f"p{i}" for i in range(n - len(named))])


@pytest.mark.parametrize("source, wide", [
    (f"def f({_params(12)}): pass", False),
    (f"def f({_params(13)}): pass", True),
    (f"def f({_params(11)}, *a, **k): pass", True),  # *args and **kwargs count
    (f"def f({_params(10)}, *, a, b, c): pass", True),  # so do keyword-only ones
    (f"f = lambda {_params(13)}: 0", True),
    (f"class C:\n    def m(self, {_params(12)}): pass", True),
    (f"def outer():\n    @jit\n    def k({_params(13)}): pass", True),  # a kernel without records
    # the record rule: one table record, one scratch record, at most 12 more
    (f"@jit_inner\ndef k({_params(14, 'tab', 'ws')}): pass", False),
    (f"@jit(parallel=True)\ndef k({_params(14, 'rec', 'scratch')}): pass", False),
    (f"@_jit.jit_typed(sig)\ndef k({_params(14, 'prm', 'ws')}): pass", False),
    (f"@jit\ndef k({_params(15, 'tab', 'ws')}): pass", True),  # 13 of block data
    (f"@jit\ndef k({_params(14, 'tab', 'rec', 'ws')}): pass", True),  # two table records
    (f"@jit\ndef k({_params(14, 'tab')}): pass", True),  # no scratch record
    (f"@lru_cache\ndef k({_params(14, 'tab', 'ws')}): pass", True),  # not a kernel
])
def test_the_rule_itself(source, wide):
    assert bool(too_wide(textwrap.dedent(source))) == wide
