"""Risk-aware charging: schedules (:mod:`.schedule`), the LP/MILP (:mod:`.lp`), the
Monte Carlo assessment (:mod:`.assess`) and the public planner (:mod:`.plan`)."""
