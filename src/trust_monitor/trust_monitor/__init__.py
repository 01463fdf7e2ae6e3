"""Explicability score, performance level and trust dynamics of the human follower.

Ozkan & Ma, eqs. (8)-(11).
"""
