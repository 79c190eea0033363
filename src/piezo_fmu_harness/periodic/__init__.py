"""The damper under harmonic base motion, shared by the studies of the forced response (the
frequency response, the continuation, the optimiser's forced objective):

- :mod:`.drive`: the FMU driven by the base ``y = Y sin(w t + phi)``, the section state and the
  measures of an orbit;
- :mod:`.steady_state`: the steady state at one frequency, a stable orbit or a motion that is not
  periodic, found as :mod:`.settings` says;
- :mod:`.stability`: the Floquet multipliers of an orbit;
- :mod:`.attraction`: whether the trajectory goes to the orbit Newton found (the response is the
  motion a start's trajectory reaches);
- :mod:`.motion`: what a motion that is not periodic is, from one window of it;
- :mod:`.band`: a band of frequencies as the options ask for it, and one frequency's steady state as
  a task of the sweep engine.
"""
