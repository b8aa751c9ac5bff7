"""seqrun: a declarative, validated sequence runner for PowerCube robot arms.

Layers (each only imports the ones above it):

    powercube.protocol, powercube.codec   pure wire format (no I/O)
    powercube.client                      request/acknowledge over any can.BusABC
    sim                                   a faithful simulated LWA 3 behind the python-can API
    arm, kinematics, planner              arm description -> forward kinematics -> ruckig plans
    yamlsource, schema, validation        sequence files -> validated steps with file:line:col
    executor, steps                       runs steps against the client, emits events
    runlog, cli                           logs and the operator's command line
"""

__version__ = "0.1.0"
