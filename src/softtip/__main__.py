"""``python -m softtip``: the same application as the ``softtip`` command."""

from softtip.cli.main import app

app(prog_name="softtip")
