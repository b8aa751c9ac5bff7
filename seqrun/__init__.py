"""seqrun: a declarative, validated sequence runner for PowerCube robot arms.

The folders are the layers; each imports only the ones listed before it
(docs/architecture.md, checked by tests/test_architecture.py):

    (base)      errors, clock, events, results, yamlsource, ...   shared by every layer
    powercube/, sim/    the wire format, the bus client, a faithful simulated LWA 3
    arm/                the arm description, kinematics, IK, geometry, ruckig plans (pure)
    drivers/            the arm-driver seam: the executor's arm, in joints (PowerCube behind it)
    steps/, schema.py, sequence/   sequence files -> validated steps with file:line:col
    executor.py         runs validated steps against a driver, emits typed events
    service/, report/   the arm session every face uses; runs, dry runs, run folders, reports
    cli/, console/      the faces: the command line and the operator console
"""

__version__ = "0.1.0"
