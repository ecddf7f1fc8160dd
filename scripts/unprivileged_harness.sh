#!/bin/bash
# Run a command as an unprivileged user that owns a delegated cgroup v1 subtree (docs/isolation.md,
# "Without root"). Run as root; the subtree is made under this shell's own cgroups and removed after.
#
#   scripts/unprivileged_harness.sh .venv/bin/python -m pytest -p no:cacheprovider tests/test_isolation.py
#
# EB_USER (default 65534, nobody) is the user id. If the interpreter lives under a folder that user
# cannot enter (e.g. a pyenv under /root), EB_BIND=/root/.pyenv makes that folder visible to the
# command only (in a private mount namespace: /root becomes an empty tmpfs with it inside). EB_BIND
# takes several folders separated by ':' (a venv in a 0700 folder of /tmp and a pyenv under /root).
set -euo pipefail
EB_USER=${EB_USER:-65534}
name=earthbench-delegated-$$
dirs=()
home=""
cleanup() {
  [ -n "$home" ] && rm -rf "$home"
  for d in "${dirs[@]}"; do
    for s in "$d"/*/; do [ -d "$s" ] && rmdir "$s" 2>/dev/null || true; done
    rmdir "$d" 2>/dev/null || true
  done
}
trap cleanup EXIT
for c in memory cpuset cpuacct freezer pids; do
  own=$(awk -F: -v c="$c" '{ n = split($2, a, ","); for (i = 1; i <= n; i++) if (a[i] == c) print $3 }' /proc/self/cgroup)
  mount=$(awk -v c="$c" '$3 == "cgroup" { n = split($4, o, ","); for (i = 1; i <= n; i++) if (o[i] == c) print $2 }' /proc/mounts | head -1)
  [ -n "$mount" ] || { echo "no cgroup v1 $c controller mounted" >&2; exit 2; }
  d=$mount${own%/}/$name
  mkdir "$d"
  dirs+=("$d")
  if [ "$c" = cpuset ]; then
    cat "$(dirname "$d")/cpuset.cpus" > "$d/cpuset.cpus"
    cat "$(dirname "$d")/cpuset.mems" > "$d/cpuset.mems"
  fi
  chown -R "$EB_USER:$EB_USER" "$d"
done
home=$(mktemp -d "${TMPDIR:-/tmp}/earthbench-unprivileged.XXXXXX")
chown "$EB_USER:$EB_USER" "$home"
DIRS="${dirs[*]}" EB_BIND=${EB_BIND:-} EB_USER=$EB_USER HOME_DIR=$home unshare -m --propagation private bash -c '
  set -e
  IFS=: read -r -a binds <<< "$EB_BIND"
  keeps=()
  for b in "${binds[@]}"; do  # set every folder aside first: a tmpfs over one parent hides the next
    keep=$(mktemp -d)
    mount --bind "$b" "$keep"
    keeps+=("$keep")
  done
  parents=$(for b in "${binds[@]}"; do dirname "$b"; done | sort -u)
  for parent in $parents; do mount -t tmpfs -o mode=755 tmpfs "$parent"; done
  for i in "${!binds[@]}"; do
    mkdir -p "${binds[$i]}"
    mount --bind "${keeps[$i]}" "${binds[$i]}"
  done
  for d in $DIRS; do echo $$ > "$d/cgroup.procs"; done
  exec setpriv --reuid="$EB_USER" --regid="$EB_USER" --clear-groups env -i PATH=/usr/bin:/bin LANG=C.UTF-8 \
    PYTHONDONTWRITEBYTECODE=1 HOME="$HOME_DIR" TMPDIR="$HOME_DIR" EARTHBENCH_PREPARED="$HOME_DIR/prepared" "$@"
' bash "$@"
