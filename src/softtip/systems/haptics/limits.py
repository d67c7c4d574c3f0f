"""The largest sizes S3's command-line options and files may ask for, one place for both: a file is
refused above the same limit, in the same words, as the option that sets the same size; and the
rendering methods by name. Plain values, so the command line checks its options before any of the
system's modules load."""

LOOP_RATE_HZ = 1000.0  # the render loop's rate: one wanted wrench a tick
MAX_DURATION_S = 3600.0  # a rendering, from --duration or a sensation file's span: the sequence is built in memory
MAX_SENSATION_ROWS = int(MAX_DURATION_S * LOOP_RATE_HZ)  # one row a tick over the longest rendering
MAX_FS_LEVELS = 31  # 29,791 configurations: a real collection of about nine hours
MAX_TABLE_ENTRIES = MAX_FS_LEVELS**3  # a recorded table's rows: the largest FS table --fs-levels collects
MAX_TARGETS = 10_000  # a protocol's trials: 100 times the published 100
MAX_TARGET_DRAWS = 1_000_000  # random configurations tried for targets: 50 times the shipped 20,000
MAX_NEIGHBOURS = 64
MAX_FINGERTIP_FILES = 12  # a protocol's own fingertips, beside its named ones: twice the published six
# a protocol's simulated presses (every configuration driven and read, softtip.systems.haptics.bench.haptics_size):
# 25 times the shipped protocol's 40,467: a few minutes on a 2-core machine
MAX_SIMULATED_PRESSES = 1_000_000

LEVELS_EXPECTED = f"an integer from 2 to {MAX_FS_LEVELS} (a table of levels³ configurations)"
DURATION_EXPECTED = f"at most {MAX_DURATION_S:g} s (the sequence is built in memory)"

SHORT_NAMES = ("standard", "A", "B", "B+", "A+")  # the study's methods (.study.METHODS) as plots and options name them
METHOD_ALIASES = {"data-driven": "A", "geometric": "B"}  # the publication's names of A and B
USER_DATA_METHODS = ("A", "B+", "A+")  # methods that drive configurations on the user's fingertip first
