"""The physics core: small numba kernels, plain arrays in and out, no allocation in the step loop.

    jit.py       `@kernel`: how every kernel here is compiled (njit, cached, no reference counting, NumPy's error model)
    constants.py the names the core shares: EPS, the contact modes, a slide's hand-over states
    events.py    the columns of the events' table: class (update protocol), bracketing, restart, component
    model.py     the Kessler-O'Reilly equations (dimensionless right-hand side, energy, steady motion)
    layout.py    named slots of the state, contact-state, work, settings and statistics arrays and
                 of the output rows, and the groups the kernels pass (namedtuples): the run's
                 buffers (Work, Record), constants (RunConsts) and the four together (Run), the
                 system a right-hand side evaluates (System) and one evaluation (Eval), a step's
                 ends (Point), its dense output and its kept part (Span, Segment), an event's
                 bracket (Bracket), a step's Hermite data (Hermite), a normal-force maximum (Peak)
    contact_rhs.py  the right-hand side per contact state (roll, slide, slaved slip), the slip speeds
    slip.py      slip onset, hand-over between slide and slaved slip, a slow slide's fate
    moments.py   the dry-friction moment components (Filippov): stick test, stop at spin_tol, signs
    event_rules.py  the events' table: each event's row beside its value and update functions
    event_codegen.py  generates event_ids.py (ids, table) and event_dispatch.py (the dispatch) from it
    impulse.py   plastic contact impulse (side change)
    tableau.py   DOP853 coefficients
    dop853_sums.py  the tableau's sums as straight-line code, generated from tableau.py
    dop853.py    step, error norm, dense output, starting step, for a right-hand side and error
                 scales passed in (it knows no state layout)
    controller.py step-size control (the factor after an error norm), apart from the method
    roots.py     event location and Phi maxima on the dense output
    tracking.py  halt levels, samples, normal-force maxima, trajectory
    frequency.py precession, ringing and f_hat at the levels over whole precession cycles
    scan.py      the event scan of an accepted step (first_event)
    accept.py    a step's try and acceptance: error norm scales of this state, energy balance, counters
    integrate.py the main loop (`run`) and its CPU entry point (`integrate`)
    fits.py      the summary's fits: halt time (also after the halt, on deeper levels), ramp exponent
    ensemble.py  one scene on fixed-size buffers (the batch path)

Everything here decides the result of a scene: the sweep's chunk fingerprint hashes this package.
"""
