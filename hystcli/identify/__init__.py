from ._old import *  # noqa: F401,F403  (temporary while the package is built)
from ._old import (check_sweep, find_reversals, identify, plot_identification,  # noqa: F401
                   Identification, KnobFit, SweepCheck, BranchFit)
