"""The expressions of ``wait_until`` and ``check``: a small, safe language over telemetry.

An expression is parsed with Python's :mod:`ast` and only a whitelist of its nodes is
accepted: numbers and ``true``/``false``, names of the telemetry namespace (``tool.z_mm``,
``gripper.holding``, ``step_time_s``), a joint's value by its number (``pos_deg[2]`` is j2:
joints are counted from 1, as the arm file names them), ``+ - * /``, comparisons (chained as
in ``-5 < pos_deg[1] < 5``), ``and``/``or``/``not``, ``abs``, ``min`` and ``max``. Nothing
is ever handed to ``eval``: :meth:`Expression.evaluate` walks the checked tree.

Every expression is checked when the sequence is loaded: its names, the joint numbers,
its types (a comparison gives a truth value, arithmetic wants numbers) and its units, read
from the names' suffixes (``_deg``, ``_mm``, ``_deg_s``, ``_a``, ``_s``, ``_n``): ``pos_deg[1]
< tool.z_mm`` compares degrees with millimetres and is refused. A plain number takes the
unit of what it meets. Pure: no I/O, no clock.
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["JOINT_SERIES", "NAMES", "Expression", "ExpressionError", "parse"]


class ExpressionError(ValueError):
    """An expression that cannot be used; ``column`` is 1-based within the text."""

    def __init__(self, message: str, column: int = 1) -> None:
        super().__init__(message)
        self.message = message
        self.column = column


#: The per-joint series: ``NAME[J]`` for joint J (1-based). Their unit is their suffix.
JOINT_SERIES: dict[str, str] = {
    "pos_deg": "deg",                   # measured position, user degrees
    "vel_deg_s": "deg/s",               # measured velocity (slope of the last readings)
    "following_error_deg": "deg",       # commanded minus measured
    "target_deg": "deg",                # what the joint was last commanded
    # the module's actual current (PowerCube Cur), read when the expression is evaluated:
    # not in the control loop, so not in a monitor
    "current_a": "A",
}

#: The scalar names: name -> (type, unit). Types: "number" or "bool".
NAMES: dict[str, tuple[str, str | None]] = {
    "tool.x_mm": ("number", "mm"),
    "tool.y_mm": ("number", "mm"),
    "tool.z_mm": ("number", "mm"),
    "tool.roll_deg": ("number", "deg"),
    "tool.pitch_deg": ("number", "deg"),
    "tool.yaw_deg": ("number", "deg"),
    "gripper.width_mm": ("number", "mm"),
    "gripper.holding": ("bool", None),
    "gripper.moving": ("bool", None),
    "step_time_s": ("number", "s"),
    "sequence_time_s": ("number", "s"),
    "moving": ("bool", None),           # any joint reports motion
}

_ARITHMETIC: dict[type, Callable[[float, float], float]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
    ast.Div: operator.truediv,
}
_COMPARE: dict[type, Callable[[Any, Any], bool]] = {
    ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
    ast.Eq: operator.eq, ast.NotEq: operator.ne,
}
_FUNCTIONS: dict[str, Callable[..., float]] = {"abs": abs, "min": min, "max": max}
_WORDS = {"true": True, "false": False}


@dataclass(frozen=True)
class _Type:
    kind: str           # "number" | "bool"
    unit: str | None    # None: a plain number (takes the unit it meets), or no unit


def _dotted(node: ast.expr) -> str | None:
    """``tool.z_mm`` for the attribute chain tool -> z_mm; None for anything else."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


class Expression:
    """A checked expression: its text, the names it reads and the joints it indexes."""

    def __init__(self, text: str, tree: ast.expr, result: _Type, names: frozenset[str],
                 joints: frozenset[int]) -> None:
        self.text = text
        self._evaluate = _compiled(tree)
        self.is_condition = result.kind == "bool"
        self.unit = result.unit
        #: Every telemetry name it reads (``pos_deg``, ``tool.z_mm``, ...).
        self.names = names
        #: Every joint number it indexes (1-based).
        self.joints = joints

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"

    def evaluate(self, values: Mapping[str, Any]) -> Any:
        """The value with the telemetry ``values`` (name -> number, bool, or a per-joint
        sequence in joint order). :raises ExpressionError: a value it needs is missing or
        not a number (e.g. no target after a Halt)."""
        return self._evaluate(values)


Evaluator = Callable[[Mapping[str, Any]], Any]


def _compiled(node: ast.expr) -> Evaluator:
    """``node`` (checked by :class:`_Checker`) as a tree of closures: evaluated every
    control cycle, it walks no syntax tree and dispatches on no node type."""
    if isinstance(node, ast.Constant):
        constant = node.value
        return lambda values: constant
    if isinstance(node, ast.Name) and node.id in _WORDS:
        word = _WORDS[node.id]
        return lambda values: word
    if isinstance(node, (ast.Name, ast.Attribute)):
        return _reader(_dotted(node) or "")
    if isinstance(node, ast.Subscript):
        return _joint_reader(node)
    if isinstance(node, ast.UnaryOp):
        operand = _compiled(node.operand)
        if isinstance(node.op, ast.Not):
            return lambda values: not operand(values)
        if isinstance(node.op, ast.UAdd):
            return operand
        return lambda values: -operand(values)
    if isinstance(node, ast.BinOp):
        return _arithmetic(node)
    if isinstance(node, ast.BoolOp):
        parts = [_compiled(v) for v in node.values]
        if isinstance(node.op, ast.And):
            return lambda values: all(part(values) for part in parts)
        return lambda values: any(part(values) for part in parts)
    if isinstance(node, ast.Compare):
        return _comparison(node)
    if isinstance(node, ast.Call):
        assert isinstance(node.func, ast.Name)
        function = _FUNCTIONS[node.func.id]
        args = [_compiled(a) for a in node.args]
        return lambda values: function(*(arg(values) for arg in args))
    raise ExpressionError("cannot evaluate this", node.col_offset + 1)  # checked: never


def _reader(name: str) -> Evaluator:
    def read(values: Mapping[str, Any]) -> Any:
        value = values.get(name)
        if value is None:
            raise ExpressionError(f"{name} has no value now")
        return value
    return read


def _joint_reader(node: ast.Subscript) -> Evaluator:
    series = _dotted(node.value) or ""
    assert isinstance(node.slice, ast.Constant) and type(node.slice.value) is int
    index: int = node.slice.value
    column = node.col_offset + 1

    def read(values: Mapping[str, Any]) -> Any:
        joints = values.get(series)
        value = None if joints is None else joints[index - 1]
        if value is None or value != value:  # (NaN: no value either)
            raise ExpressionError(f"{series}[{index}] has no value now", column)
        return value
    return read


def _arithmetic(node: ast.BinOp) -> Evaluator:
    left, right = _compiled(node.left), _compiled(node.right)
    op = _ARITHMETIC[type(node.op)]
    if not isinstance(node.op, ast.Div):
        return lambda values: op(left(values), right(values))
    column = node.col_offset + 1

    def divide(values: Mapping[str, Any]) -> Any:
        divisor = right(values)
        if divisor == 0:
            raise ExpressionError("division by zero", column)
        return left(values) / divisor
    return divide


def _comparison(node: ast.Compare) -> Evaluator:
    first = _compiled(node.left)
    steps = [(_COMPARE[type(op)], _compiled(c)) for op, c in
             zip(node.ops, node.comparators, strict=True)]
    if len(steps) == 1:
        (op, right), = steps
        return lambda values: op(first(values), right(values))

    def chain(values: Mapping[str, Any]) -> bool:
        left = first(values)
        for op, comparator in steps:
            right = comparator(values)
            if not op(left, right):
                return False
            left = right
        return True
    return chain


def parse(text: str, *, params: Mapping[str, tuple[str, str | None]] | None = None,
          joints: int | None = None) -> Expression:
    """Parse and check ``text``. ``params``: the sequence's parameters (name -> (type,
    unit)), read as ``params.NAME``; ``joints``: how many joints the arm has (None: any
    joint number from 1 is accepted here and checked against the arm later).

    :raises ExpressionError: with the column of the first problem.
    """
    if not isinstance(text, str) or not text.strip():
        raise ExpressionError("an expression is needed here (e.g. 'tool.z_mm > 40')")
    if "\n" in text.strip():
        raise ExpressionError("an expression is one line")
    source = text.strip()
    try:
        tree = ast.parse(source, mode="eval").body
    except SyntaxError as exc:
        raise ExpressionError(f"not an expression: {exc.msg}", exc.offset or 1) from None
    checker = _Checker(params or {}, joints)
    result = checker.type_of(tree)
    return Expression(source, tree, result, frozenset(checker.names), frozenset(checker.joints))


class _Checker:
    """Types and units of every node, refusing what the language does not have."""

    def __init__(self, params: Mapping[str, tuple[str, str | None]], joints: int | None) -> None:
        self.params = params
        self.max_joint = joints
        self.names: set[str] = set()
        self.joints: set[int] = set()

    def fail(self, node: ast.AST, message: str) -> ExpressionError:
        return ExpressionError(message, getattr(node, "col_offset", 0) + 1)

    def type_of(self, node: ast.expr) -> _Type:
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool):
                raise self.fail(node, "write true or false (lower case)")
            if isinstance(node.value, (int, float)):
                return _Type("number", None)
            raise self.fail(node, f"{node.value!r} is not a number: expressions compare "
                                  "numbers and truth values")
        if isinstance(node, ast.Name) and node.id in _WORDS:
            return _Type("bool", None)
        if isinstance(node, (ast.Name, ast.Attribute)):
            return self.name_type(node)
        if isinstance(node, ast.Subscript):
            return self.joint_value(node)
        if isinstance(node, ast.UnaryOp):
            operand = self.type_of(node.operand)
            if isinstance(node.op, ast.Not):
                self.want(node.operand, operand, "bool", "not")
                return _Type("bool", None)
            if isinstance(node.op, (ast.USub, ast.UAdd)):
                self.want(node.operand, operand, "number", "a sign")
                return operand
            raise self.fail(node, "this operator is not part of the language")
        if isinstance(node, ast.BinOp):
            if type(node.op) not in _ARITHMETIC:
                raise self.fail(node, "only + - * / are arithmetic here")
            left, right = self.type_of(node.left), self.type_of(node.right)
            self.want(node.left, left, "number", "arithmetic")
            self.want(node.right, right, "number", "arithmetic")
            if isinstance(node.op, (ast.Add, ast.Sub)):
                return _Type("number", self.same_unit(node, left, right, "add or subtract"))
            if isinstance(node.op, ast.Mult):
                unit = left.unit if right.unit is None else right.unit if left.unit is None \
                    else f"{left.unit}*{right.unit}"
                return _Type("number", unit)
            unit = left.unit if right.unit is None else None if left.unit == right.unit \
                else f"{left.unit or '1'}/{right.unit}"
            return _Type("number", unit)
        if isinstance(node, ast.BoolOp):
            for value in node.values:
                self.want(value, self.type_of(value), "bool",
                          "and" if isinstance(node.op, ast.And) else "or")
            return _Type("bool", None)
        if isinstance(node, ast.Compare):
            left = self.type_of(node.left)
            for op, comparator in zip(node.ops, node.comparators, strict=True):
                if type(op) not in _COMPARE:
                    raise self.fail(node, "only < <= > >= == != compare here")
                right = self.type_of(comparator)
                if left.kind != right.kind:
                    raise self.fail(comparator, f"compares a {left.kind} with a {right.kind}")
                if left.kind == "bool" and not isinstance(op, (ast.Eq, ast.NotEq)):
                    raise self.fail(comparator, "truth values compare with == or != only")
                self.same_unit(comparator, left, right, "compare")
                left = right
            return _Type("bool", None)
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in _FUNCTIONS:
                raise self.fail(node, "the only functions are abs, min and max")
            if node.keywords or not node.args or \
                    (node.func.id == "abs" and len(node.args) != 1) or \
                    (node.func.id != "abs" and len(node.args) < 2):
                raise self.fail(node, f"{node.func.id} takes "
                                      f"{'one number' if node.func.id == 'abs' else 'two or more numbers'}")
            types = [self.type_of(a) for a in node.args]
            unit = None
            for arg, type_ in zip(node.args, types, strict=True):
                self.want(arg, type_, "number", node.func.id)
                unit = self.same_unit(arg, _Type("number", unit), type_, node.func.id)
            return _Type("number", unit)
        if isinstance(node, ast.IfExp):
            raise self.fail(node, "no 'if' inside an expression: use the step's if:")
        raise self.fail(node, "this is not part of the expression language "
                              "(numbers, telemetry names, + - * /, comparisons, and/or/not, "
                              "abs/min/max)")

    def want(self, node: ast.expr, type_: _Type, kind: str, what: str) -> None:
        if type_.kind != kind:
            raise self.fail(node, f"{what} needs a {'number' if kind == 'number' else 'truth value'}"
                                  f" here, not a {type_.kind}")

    def same_unit(self, node: ast.expr, left: _Type, right: _Type, what: str) -> str | None:
        if left.unit is None:
            return right.unit
        if right.unit is None or right.unit == left.unit:
            return left.unit
        raise self.fail(node, f"cannot {what} {left.unit} and {right.unit}")

    def name_type(self, node: ast.expr) -> _Type:
        name = _dotted(node)
        if name is None:
            raise self.fail(node, "not a telemetry name")
        if name in JOINT_SERIES:
            raise self.fail(node, f"{name} is per joint: write {name}[J], J the joint's number "
                                  "(1 = j1)")
        if name.startswith("params."):
            key = name.removeprefix("params.")
            if key not in self.params:
                raise self.fail(node, f"no parameter '{key}' is declared under params:")
            kind, unit = self.params[key]
            self.names.add(name)
            return _Type(kind, unit)
        if name not in NAMES:
            raise self.fail(node, f"unknown name '{name}' (the names are in docs/"
                                  "sequence-format.md, 'Expressions')")
        self.names.add(name)
        kind, unit = NAMES[name]
        return _Type(kind, unit)

    def joint_value(self, node: ast.Subscript) -> _Type:
        series = _dotted(node.value)
        if series not in JOINT_SERIES:
            raise self.fail(node, f"only the per-joint series take [J]: "
                                  f"{', '.join(JOINT_SERIES)}")
        index = node.slice
        if not (isinstance(index, ast.Constant) and type(index.value) is int):
            raise self.fail(index, "a joint's number is a whole number, e.g. pos_deg[2]")
        number = index.value
        if number < 1 or (self.max_joint is not None and number > self.max_joint):
            top = f"1 to {self.max_joint}" if self.max_joint is not None else "from 1"
            raise self.fail(index, f"joint number {number} is not one of the arm's ({top})")
        self.names.add(series)
        self.joints.add(number)
        return _Type("number", JOINT_SERIES[series])
