"""Many runs (layer `studies`): scenarios, TOML to objects (:mod:`.scenarios`), one-at-a-time studies (:mod:`.study`),
sweeps (:mod:`.sweep`) and the comparison of every law (:mod:`.compare`); tables, no figures."""
