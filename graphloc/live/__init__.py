"""Live use: a running team's rows pushed as they arrive, one iSAM2 update per completed time
step (`LiveTeam`); the incremental team graph behind it (`builder.LiveGraph`)."""
