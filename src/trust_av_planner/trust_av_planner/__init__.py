"""Trust-aware nonlinear MPC for the automated vehicle, in-process simulator and CLI."""
