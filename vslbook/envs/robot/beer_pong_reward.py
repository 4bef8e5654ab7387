"""The reward of Beer Pong (thesis Section 3.4, Appendix A.3.2): the return of an executed
episode, :func:`beer_pong_reward`, and what "in the cup" and "contact" mean in each of the
:data:`REWARD_VARIANTS` (the environment, :mod:`vslbook.envs.robot.beer_pong`, judges them).

**Reward** (A.3.2; the episode return):

* cond. 1, not in the cup, no contact:
  −4 − min_t ‖p_c,top − p_b,t‖² − 0.5 ‖p_c,bottom − p_b,T‖² − 10⁻⁴ τ̄
* cond. 2, not in the cup, contact: −2 − (the same terms)
* cond. 3, in the cup: −‖p_c,bottom − p_b,T‖² − 1.5·10⁻⁴ τ̄

⚠ The thesis prints cond. 3 without the minus signs; that would reward a large torque and
distance, so we use the negated form of the authors' code (in the cup always beats not in
the cup). τ̄ ("the squared mean torque") is, as in the code, the mean over all simulated
steps of Σ_j u_j² with u the applied torque including the compensation term.

What "in the cup" and "contact" mean (:class:`~vslbook.envs.robot.beer_pong.BeerPong`'s
``reward``):

* ``"code"`` (default; the authors' SVSL code, which made Fig. 3.2): cond. 3 holds if the
  ball touched the cup's floor geom ``cup_base_table_contact`` at any time of the episode,
  so a ball that lands on the floor and bounces out again scores cond. 3 (with the distance
  of wherever it ends up) instead of cond. 1 or 2's −2 or −4. "Contact" (cond. 2 vs 1) is
  any contact of the ball with the table top ``table_contact_geom`` (not the table's body
  ``table`` below it), the wall ``wall`` or any geom of the cup body ``cup_table`` (its
  walls, base and floor), at any time (while in the hand too). Both are judged, as there,
  on the contact lists of the states the steps start from (the states the loop records),
  except the last step's: the authors' loop reads each step's list in the next iteration,
  so the last one is read only by their success test. Success: the ball touches the cup's
  floor in that last step's state.
* ``"thesis"`` (A.3.2's text read literally): cond. 3 and success: the ball touches the
  cup's floor in the final state; "contact" is "table contact": a contact of the ball with
  the table's geoms (``table``, ``table_contact_geom``) after release or in the final state.

The environment looks the contacts up after its simulation loop. The authors' −500 for
"self-collision" (the arm hitting the table) is not in the thesis and is left out.
An unstable simulation (non-finite state or MuJoCo's bad-acceleration warning) returns −30,
simulated, unsuccessful (code). A non-finite or huge position or velocity in mid-episode
shows only as MuJoCo's warning (it resets the data and goes on), so its bad-position and
bad-velocity warnings count too.
"""

from __future__ import annotations

import mujoco

__all__ = [
    "CODE_CONTACT_GEOMS", "CUP_BODY", "CUP_FLOOR_GEOM", "REWARD_VARIANTS", "TABLE_GEOMS",
    "UNSTABLE_PENALTY", "UNSTABLE_WARNINGS", "beer_pong_reward",
]  # fmt: skip

UNSTABLE_PENALTY = -30.0
#: ``reward`` variants (module docstring): the authors' code (default) and A.3.2's text.
REWARD_VARIANTS = ("code", "thesis")
#: "Table contact" of A.3.2's text (``reward="thesis"``).
TABLE_GEOMS = ("table", "table_contact_geom")
#: The contacts of cond. 2 in the authors' code (``reward="code"``): these geoms and every
#: collision geom of the cup body :data:`CUP_BODY`.
CODE_CONTACT_GEOMS = ("table_contact_geom", "wall")
CUP_BODY = "cup_table"
CUP_FLOOR_GEOM = "cup_base_table_contact"
#: MuJoCo's warnings of an unstable simulation: a non-finite or huge position or velocity
#: (MuJoCo then resets the data, so the bad state itself is gone) or acceleration.
UNSTABLE_WARNINGS = tuple(
    int(w) for w in (
        mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
        mujoco.mjtWarning.mjWARN_BADQACC,
    )
)  # fmt: skip


def beer_pong_reward(
    in_cup: bool,
    table_contact: bool,
    min_dist_top: float,
    final_dist_bottom: float,
    torque_cost: float,
) -> float:
    """The return of an executed episode (A.3.2's R(θ, c), cond. 3 with the minus sign, see
    the module docstring).

    Args:
        in_cup: cond. 3, the ball is in the cup (module docstring: when, per ``reward``).
        table_contact: cond. 2 vs cond. 1, the ball had contact (module docstring: with
            what, per ``reward``).
        min_dist_top: min_t ‖p_c,top − p_b,t‖ (not squared).
        final_dist_bottom: ‖p_c,bottom − p_b,T‖ (not squared).
        torque_cost: τ̄, the mean over steps of Σ_j u_j².
    """
    if in_cup:
        return -(final_dist_bottom**2) - 1.5e-4 * torque_cost
    offset = -2.0 if table_contact else -4.0
    return offset - min_dist_top**2 - 0.5 * final_dist_bottom**2 - 1e-4 * torque_cost
