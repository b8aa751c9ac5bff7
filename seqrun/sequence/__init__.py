"""Sequence files: campaigns, loading (includes, frozen poses), static validation, references.

The file format itself is :mod:`seqrun.schema` (the step kinds' models, from
:mod:`seqrun.steps`); this package reads files in that format and checks them against an arm.
"""
