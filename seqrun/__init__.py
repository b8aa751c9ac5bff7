"""seqrun: a declarative, validated sequence runner for PowerCube robot arms.

The folders are the layers; each imports only the ones listed before it
(docs/architecture.md, checked by tests/test_architecture.py):

    (base)      errors, clock, events, results, yamlsource, runfolder/, ...   shared by all
    powercube/, sim/    the wire format, the bus client, a faithful simulated LWA 3
    arm/                the arm description, kinematics, IK, geometry, ruckig plans (pure)
    drivers/            the arm-driver seam: the executor's arm, in joints (PowerCube behind it)
    steps/              the step kinds: one module each (format, check, handler)
    executor.py         runs the steps against a driver, emits typed events
    schema.py, sequence/   sequence files -> validated steps with file:line:col
    service/, report/   the arm session every face uses; runs, dry runs, run folders, reports
    cli/, console/, ros/, foxglove/   the faces; __main__.py the program
"""

__version__ = "0.1.0"
