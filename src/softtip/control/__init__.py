"""Feedback control from the fingertips' estimates: the insertion task's loop (:mod:`~softtip.control.insertion`)."""

from softtip.control.insertion import Decision, InsertionController, Robot

__all__ = ["Decision", "InsertionController", "Robot"]
