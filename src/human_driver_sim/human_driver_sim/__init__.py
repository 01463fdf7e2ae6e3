"""IRL-style MPC model of the human driver following the AV (Ozkan & Ma, eq. 13)."""

__all__: list[str] = []

