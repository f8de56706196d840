"""twin_croc: a receding-horizon planner on the field's optimal-control stack, Crocoddyl + mim-solvers
(constrained SQP) with pinocchio (extra `croc`). Issue 28, in progress: so far the arm's pinocchio model,
equal to twin's kinematics (`twin_croc.model`); the planner is not registered yet.

Import pinocchio or crocoddyl before mim_solvers: imported first, mim_solvers fails on a missing boost library
(libboost_atomic, which pinocchio's import loads)."""
