"""The executor's parts, each a room of its own; :mod:`seqrun.executor` is the front door
(the run loop, and what a step handler may use of it).

run.py         the run as its parts see it (a protocol the executor implements),
               one reading of the arm (Measurement)
preflight.py   read the arm, validate again from where it stands
latched.py     faults latched before the run: told, cleared only with the operator's word
streaming.py   moves streamed cycle by cycle, controlled stop, pause, waits
checks.py      the checks of every reading: state flags, guards, link volumes
stops.py       stop requests as the loop takes them (abort, Halt, pause)
ending.py      the emergency Halt, fault records, the run's result
telemetry.py   the subscribers' fields of a reading (velocities, flags)
"""
