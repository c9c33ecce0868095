"""The physics core: small numba kernels, plain arrays in and out, no allocation in the step loop.

    jit.py       `@kernel`: how every kernel here is compiled (njit, cached, no reference counting, NumPy's error model)
    constants.py the names the core shares: EPS, the contact modes, a slide's hand-over states
    events.py    the events as one table (ids = rows): class, bracketing, restart, component
    model.py     the Kessler-O'Reilly equations (dimensionless right-hand side, energy, steady motion)
    layout.py    named slots of the state, contact-state, work, settings and statistics arrays and
                 of the output rows, and the groups the kernels pass (namedtuples): the run's
                 buffers (Work, Record) and constants (RunConsts), the system a right-hand side
                 evaluates (System), a step's ends (Point), its dense output and its kept part
                 (Span, Segment)
    contact.py   contact modes (roll, slide, slaved slip), event functions, discrete updates
    impulse.py   plastic contact impulse (side change)
    tableau.py   DOP853 coefficients
    dop853_sums.py  the tableau's sums as straight-line code, generated from tableau.py
    dop853.py    step, error norm, dense output, starting step, for a right-hand side and error
                 scales passed in (it knows no state layout)
    controller.py step-size control (the factor after an error norm), apart from the method
    roots.py     event location and Phi maxima on the dense output
    tracking.py  halt levels, samples, normal-force maxima, trajectory
    frequency.py precession, ringing and f_hat at the levels over whole precession cycles
    integrate.py the main loop (`run`), its CPU entry point (`integrate`), the error norm's scales of
                 this state (error_scale)
    fits.py      the summary's fits: halt time (also after the halt, on deeper levels), ramp exponent
    ensemble.py  one scene on fixed-size buffers (the batch path)

Everything here decides the result of a scene: the sweep's chunk fingerprint hashes this package.
"""
