"""What every block of one lane's generated code stands on: the text being written, the
parameter names, the contact-law rows, and the kernels' functions inlined as text.

:class:`LaneText` is the base of :class:`mcchain.codegen.kinematics.ConstraintKinematics`
and :class:`mcchain.codegen.emitter.Emitter`. Names in the generated code: ``q{i}``,
``v{i}`` the lane's coordinates and velocities, ``t`` the time, ``p_<slot>`` the parameters
(loaded by :meth:`LaneText.load_params`), ``lam{r}`` the multipliers, ``qdd{i}`` the
accelerations.
"""

from __future__ import annotations

import ast
from collections.abc import Callable

from mcchain.codegen.inline import inline
from mcchain.codegen.sparse_ldl import Coef
from mcchain.codegen.topology import Topology
from mcchain.model import GROUND

CONTACT_KERNELS = "mcchain.kernels.contact"
"""The module whose functions define the contact law for the loop kernels and the lanes."""
JOINT_KERNELS = "mcchain.kernels.joints"
"""… the joints' and drivers' arithmetic (points, Φ, Φ̇, γ, B's turning entries)."""
FORCE_KERNELS = "mcchain.kernels.forces"
"""… the applied forces' arithmetic (loads, spring-dampers, moments, energies)."""


def _tidy(text: str) -> str:
    """``text`` with the parentheses it does not need dropped (a composed expression)."""
    return ast.unparse(ast.parse(text, mode="eval"))


def _coef(text: str) -> Coef:
    """A coefficient of B from an inlined expression: a literal as its float, a name as it
    is, anything else in parentheses (it becomes a factor of products)."""
    try:
        return float(text)
    except ValueError:
        pass
    return text if isinstance(ast.parse(text, mode="eval").body, ast.Name) else f"({text})"


class LaneText:
    """The lines of one lane's code being written for a :class:`Topology`, and the names
    they use. Methods append lines and return nothing (or the expressions of an inlined
    function's results); :meth:`take` returns the lines written since the last call."""

    def __init__(self, topo: Topology):
        self.topo = topo
        self.slots = topo.slots()
        self.lines: list[str] = []
        names = {i: f"p_{name}" for name, i in self.slots.items()}
        self._where: Callable[[int], str] = names.__getitem__  # before load_params: the names
        # Contact-law joints: joint -> its constraint row; the per-lane state they read
        # (fm: law active, ins: in contact at the step's start, vi: approach speed δ̇⁻).
        self.contact_row = {k: topo.joint_row[k] for k in topo.contact_joints}
        self._contact_state: Callable[[str, int], str] = lambda name, k: "0.0"
        self.hertz_exponent = False
        """Write every contact joint's exponent as the literal 1.5 (a copy of the stage for
        lane groups whose exponents all are: ``contact_power`` without ``pow``)."""

    def contact_source(self, where: Callable[[str, int], str]) -> None:
        """Where the contact state ``fm``/``ins``/``vi`` of joint k is read (default 0: the
        link, as in the Python-facing kernels)."""
        self._contact_state = where

    def _load_contact_state(self, *names: str) -> None:
        for k in self.contact_row:
            self.emit(*(f"{n}{k} = {self._contact_state(n, k)}" for n in names))

    def _row_law(self, r: int) -> str | None:
        """``fm{k}`` (1 while the law replaces the link, else 0) for the row of a contact
        joint, None for the other rows.

        Every blend between the link and the law is a select on it (``x if fm == 0.0 else
        y``), never a product by 0/1: under fastmath "contract" LLVM may fuse a product by
        1.0 with the next addition and round once where the link alone rounds twice, and
        the model auto must give the link's values bit for bit while the link holds.
        """
        for k, row in self.contact_row.items():
            if row == r:
                return f"fm{k}"
        return None

    # -- plumbing --------------------------------------------------------------------------
    def emit(self, *lines: str) -> None:
        self.lines.extend(lines)

    def take(self, indent: int) -> str:
        pad = " " * indent
        text = "\n".join(pad + line if line else "" for line in self.lines)
        self.lines = []
        return text

    def load_params(self, where: Callable[[int], str]) -> None:
        """``p_<slot> = where(slot index)`` for every parameter slot; later blocks may load a
        parameter again from ``where`` (:meth:`_reload`)."""
        self._where = where
        for name, i in self.slots.items():
            self.emit(f"p_{name} = {where(i)}")

    def _reload(self, name: str) -> str:
        """A fresh load of parameter ``p_<name>`` (from the last :meth:`load_params`): at the
        end of a long body a load is cheaper than keeping the value from the start."""
        return self._where(self.slots[name])

    def inline(self, function: str, arguments: list[str], k: int) -> list[str]:
        """:meth:`kernel` of ``mcchain.kernels.contact.<function>`` for joint ``k``."""
        return self.kernel(CONTACT_KERNELS, function, arguments, str(k))

    def kernel(
        self, module: str, function: str, arguments: list[str], suffix: str = ""
    ) -> list[str]:
        """Emit the text of ``module.function(*arguments)`` (:func:`mcchain.codegen.inline.
        inline`: the kernels' own definition, its locals suffixed with ``suffix``, needed
        only by a function with locals) and return the expressions of its results."""
        statements, results = inline(module, function, arguments, suffix)
        if statements and not suffix:
            raise TypeError(f"{module}.{function} has locals: give a suffix")
        self.emit(*statements)
        return results

    @staticmethod
    def _coordinates(body: int, state: str, count: int) -> list[str]:
        """The first ``count`` of (x, y, θ) of ``body`` in ``state`` (or of their rates):
        literal 0.0 for the ground."""
        return [f"{state}{3 * body + i}" if body != GROUND else "0.0" for i in range(count)]

    @staticmethod
    def _angle(body: int, q: str) -> str:
        """The angle (or angular speed, q = "v") of ``body``: the literal 0.0 for the ground."""
        return f"{q}{3 * body + 2}" if body != GROUND else "0.0"
