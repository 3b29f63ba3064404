"""Domain translation X -> Y (paper §III-C): generator G, discriminator D, eqs. 1-6.

G maps a state of domain X, in the canonical order ``[x^Ri, x^H, x^O]`` of its pairing plus a
one-hot of the pairing, to a normalised state of domain Y ``[y^R1, y^R2, y^O]``. D tells real
normalised Y states (from Y's random motion) from G's outputs. The generator's loss is

    lambda_adv * L_adv + lambda_dyn * L_dyn + lambda_id * L_id

with L_dyn = ||F(y_hat_t, F^-1(y_hat_t, y_hat_t+1)) - y_hat_t+1||^2 through the frozen dynamics
models and L_id = ||y_hat^Ri - x^Ri||^2 on the robot that is really there. The ablations are the
same code with a weight at zero (:mod:`lfdt.methods`).

Normalisation: x^Ri and x^O use Y's statistics of the same columns (so L_id compares like with
like); x^H uses the statistics of the human columns in that pairing's X random data.

Batches: half demonstration transitions, half X random-motion transitions, each half split
evenly between the two pairings; D sees as many real Y states. The human's recorded actions are
never read.

Submodules, one job each; this package imports none of them, so code that only applies a translator does not
depend on the training code:

* ``transitions``: G's input data: the canonical X columns of a pairing,
  :class:`~lfdt.translation.transitions.Transitions`, their loading and the held-out split;
* ``kinematics``: what the translator may take from Y's robot model (the arms, their end positions);
* ``model``: the translator (G, D and the X normalisers; skips, normalisers, the mean of several translators) and
  a method's translator config;
* ``losses``: eq. 6's generator losses on a batch, and all transitions of some pairings as one batch;
* ``training``: training the translators of a stack of members (G and D, checkpoint selection);
* ``restarts``: restarts of one configuration (their seeds, metric names, training);
* ``apply``: translating demonstrations, the translated table, and the diagnostics of a translator and of its
  translations.
"""
