"""The paper's simulation experiment (section 3.1, Table 2, Figs. 4 and 5): `ridgeloc simulate`.

config (typed YAML config) -> scenario (noisy trials as ObservationBatch) -> experiment (batched solves,
statistics) -> report (table2.csv/.md, fig4/fig5.png, summary.json).
"""

from pipeline.simulate.config import SimulationConfig
from pipeline.simulate.experiment import SimulationResult, run_simulation
from pipeline.simulate.report import write_outputs
from pipeline.simulate.scenario import Trials, generate

__all__ = ["SimulationConfig", "SimulationResult", "Trials", "generate", "run_simulation", "write_outputs"]
