"""softtip's benchmarks, behind ``softtip bench``: every figure is reported beside a baseline
measured in the same run (another library, a simpler solve, the published figure), because a
shared machine's absolute speeds vary from run to run and their ratios much less."""
