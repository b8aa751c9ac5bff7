"""The run folder's files as both sides see them: the run log that writes them as the run
goes (:mod:`seqrun.service.runlog`) and the report that reads them afterwards
(:mod:`seqrun.report`). Below both: imports nothing of seqrun.

:mod:`.logfile`  files that fail quietly and leave only whole lines behind
:mod:`.names`    the names of the files a run leaves (the CAN trace's)
"""
