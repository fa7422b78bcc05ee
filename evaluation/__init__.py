"""Runnable evaluation scripts (not part of the library; never imported by ``hybridev``)."""
