"""S3: personalised data-driven haptic rendering at the fingertip.

A 3-cable fingertip-mounted device (:mod:`.device`), the fingertips it presses (:mod:`.fingertips`), lookup
tables and the k-nearest-neighbour renderer (:mod:`.rendering`), the two personalisations
(:mod:`.personalisation`), the simulated table collection (:mod:`.collection`) and the published
study with its statistics (:mod:`.study`, :mod:`.statistics`).
"""
