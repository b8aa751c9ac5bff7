"""The step kinds: one module each (parameters, shorthand, description, static check and
handler), listed in :mod:`seqrun.steps.registry`
(with :data:`~seqrun.steps.registry.HANDLERS`, what the executor calls).

A handler is ``run(step, ex) -> dict | None``: it receives the resolved step (its
validated parameters and source location) and the executor as a
:class:`~seqrun.steps.context.StepContext`, whose methods do the bus work and the safety
checks; the returned dict goes into the step's report entry.
"""
