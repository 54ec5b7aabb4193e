"""How far to read a verdict: what every verdict that states an effect adds after it.

The probabilities' own record on worlds written blind to the method, a pair that may be one effect, what else
acts like a term the verdict states, which library term an "unlisted" lead may be in a law unlike the library's,
and a seating's end step that alone departs from the baseline.
"""

from __future__ import annotations

from typing import Any

from labctl.discrepancy.model import term_class
from labctl.discrepancy.posterior import LIKELY_AT, Scored
from labctl.discrepancy.search import Candidate

READ_PROBABILITIES = ("the probabilities are the method's own: on worlds written blind to it, those from 0.7 up were "
                      "right less often than stated (docs/discrepancy.md, Evaluation); before acting on a name, "
                      "`labctl plan` on the same files recommends the measurements that would best tell the "
                      "candidates apart")
"""What every verdict that states an effect says about its probabilities, and what to do before acting on them."""
PAIR_MAY_BE_ONE = ("a pair can be one effect whose law the library lacks, its second term mending the first one's "
                   "form: on worlds written blind to the method with repetitions scattering under about 1 %, single "
                   "effects were named as pairs (docs/discrepancy.md, Limits); read it as one effect until the "
                   "measurements `labctl plan` recommends separate the two terms")
"""What a verdict that states two terms adds."""
UNLISTED_MAY_BE = ("on worlds written blind to the method, where \"unlisted\" led the truth was often a library "
                   "effect in a law unlike the library's, and often the closest term (docs/discrepancy.md, "
                   "Evaluation)")
"""Why an "unlisted" lead names the library term closest to the data."""


def caveats(top: Scored | None, closest: Candidate | None) -> list[str]:
    """The words a verdict that states an effect (``top``, the most probable explanation) ends with, before the
    design's limits; ``closest``: the single library term that alone takes up most of the misfit, if any."""
    parts = [READ_PROBABILITIES]
    if top is None or top.probability < LIKELY_AT:
        return parts
    if top.explanation.kind == "pair":
        parts.append(PAIR_MAY_BE_ONE)
    parts += [f"{t} may also be {term_class(t).LOOK_ALIKE}" for t in top.explanation.terms if term_class(t).LOOK_ALIKE]
    if top.explanation.unlisted and closest is not None:
        parts.append(f"\"unlisted\" may also be {closest.name} in a law unlike the library's (the library term "
                     f"closest to the data: alone it takes up {closest.share:.0%} of the misfit); {UNLISTED_MAY_BE}")
    return parts


def end_step_words(note: dict[str, Any]) -> str:
    """What a seating's first or last step that every repetition leaves the same way, while every other step follows
    a fit, adds to a verdict (``note``: ``Screening.end_steps``'s record): it is kept, and why to check it."""
    loads = note["load_n"]
    cause = "a tilt bedding in after it" if note["step"] == "first" else "a yield setting in there"
    beyond = "below" if note["step"] == "first" else "above"
    return (f"the {note['step']} step of {note['case']}, at {loads[0]:.4g}-{loads[-1]:.4g} N, is off by "
            f"{note['off_rel'] * 100:+.1f} % in every seating while every other step follows {note['against']}: "
            f"{cause}, or a fault at that step (a load set or read wrong); the data cannot tell, so it is kept — "
            f"re-measure that step, or add one {beyond} it, before acting on the verdict")
