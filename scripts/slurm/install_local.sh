#!/usr/bin/env bash
# Installs Debian's Slurm (controller, node daemon, client) and MUNGE for a single-node test cluster.
# Idempotent; needs root and the Debian package registry. Used by the Slurm integration test
# (tests/it/slurm.rs); a real cluster has its own Slurm and needs none of this.
set -euo pipefail
need=()
for cmd in slurmctld slurmd sbatch munged; do
    command -v "$cmd" >/dev/null 2>&1 || need+=("$cmd")
done
if [ ${#need[@]} -eq 0 ]; then
    exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
    echo "install_local.sh: installing Slurm needs root (missing: ${need[*]})" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
# Package post-install scripts may try to start services; there is no init system to do so here.
if [ ! -e /usr/sbin/policy-rc.d ]; then
    printf '#!/bin/sh\nexit 101\n' > /usr/sbin/policy-rc.d
    chmod +x /usr/sbin/policy-rc.d
    trap 'rm -f /usr/sbin/policy-rc.d' EXIT
fi
apt-get update -qq
apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
echo "[slurm] installed: $(dpkg-query -W -f '${Package} ${Version}\n' slurmctld munge | tr '\n' ' ')"
