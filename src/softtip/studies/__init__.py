"""End-to-end studies: experiments on the twin, models, metrics and reports."""
