#!/bin/busybox sh
# shellcheck shell=dash
# /init of the vcan-vm initramfs (built by scripts/vcan-vm setup; runs as PID 1 in the guest).
#
#  1. mounts proc, sys, dev; loads the CAN/9p/virtio modules listed in /etc/vcan-vm/modules, in order;
#  2. mounts the host root read-only (9p tag "hostroot") at /newroot and the writable results share
#     (9p tag "results") at /results;
#  3. bind-mounts proc/sys/dev into /newroot, mounts tmpfs on /newroot/tmp and /newroot/run, binds the
#     results share at /newroot/run/vcan-vm, mounts the extra --rw/--ro shares at their host paths;
#  4. creates and brings up the vcan interfaces, prints the guest kernel version and the interface;
#  5. chroots into the host root, runs /run/vcan-vm/run.sh (cd + environment + command, written by the
#     host), writes its exit status to /results/status and powers off.
# Any failure prints "vcan-vm: FATAL: ..." (and writes /results/error when the share is mounted) and powers
# off without a status, which the host reports as a failure.
export PATH=/bin
umask 022

fatal() {
  echo "vcan-vm: FATAL: $*"
  if [ -n "$RESULTS_MOUNTED" ]; then
    echo "$*" >/results/error
    sync
  fi
  poweroff -f
  sleep 10
  exit 1
}

mount -t proc proc /proc || fatal "cannot mount /proc"
mount -t sysfs sysfs /sys || fatal "cannot mount /sys"
mount -t devtmpfs devtmpfs /dev || fatal "cannot mount devtmpfs on /dev"
[ -e /dev/fd ] || ln -s /proc/self/fd /dev/fd
[ -e /dev/stdin ] || ln -s /proc/self/fd/0 /dev/stdin
[ -e /dev/stdout ] || ln -s /proc/self/fd/1 /dev/stdout
[ -e /dev/stderr ] || ln -s /proc/self/fd/2 /dev/stderr
# The console is the host's stdout: plain "\n" line ends, no "\r".
stty -onlcr 2>/dev/null
hostname vcan-vm

echo "vcan-vm: guest kernel $(uname -r) ($(nproc) CPUs, $(awk '/MemTotal/ {print int($2/1024)}' /proc/meminfo) MiB)"

while read -r mod; do
  [ -n "$mod" ] || continue
  insmod "/lib/modules/$mod" || fatal "module $mod failed to load (insmod exit $?)"
done </etc/vcan-vm/modules
MODULES_AT=$(cut -d' ' -f1 /proc/uptime)

P9OPTS="trans=virtio,version=9p2000.L,msize=512000"
mkdir -p /newroot /results
mount -t 9p -o "$P9OPTS,cache=none" results /results || fatal "cannot mount the results share (9p tag results)"
RESULTS_MOUNTED=1
[ -r /results/config ] || fatal "no /results/config from the host"
# shellcheck disable=SC1091
. /results/config
mount -t 9p -o "$P9OPTS,cache=loose,ro" hostroot /newroot || fatal "cannot mount the host root (9p tag hostroot)"

for d in proc sys dev tmp run; do
  [ -d "/newroot/$d" ] || fatal "the host root has no /$d directory to mount on"
done
mount --bind /proc /newroot/proc || fatal "cannot bind /proc"
mount --bind /sys /newroot/sys || fatal "cannot bind /sys"
mount --bind /dev /newroot/dev || fatal "cannot bind /dev"
[ -d /newroot/dev/pts ] || mkdir -p /dev/pts
mount -t devpts -o gid=5,mode=620,ptmxmode=666 devpts /newroot/dev/pts 2>/dev/null
[ -d /newroot/dev/shm ] || mkdir -p /dev/shm
mount -t tmpfs -o mode=1777 tmpfs /newroot/dev/shm || fatal "cannot mount /dev/shm"
mount -t tmpfs -o mode=1777 tmpfs /newroot/tmp || fatal "cannot mount tmpfs on /tmp"
mount -t tmpfs -o mode=755 tmpfs /newroot/run || fatal "cannot mount tmpfs on /run"
mkdir -p /newroot/run/vcan-vm
mount --bind /results /newroot/run/vcan-vm || fatal "cannot bind the results share"

# Extra shares at the same path as on the host: VCAN_VM_SHARES="tag mode path ...", mode ro or rw.
# Under the guest's tmpfs (/tmp, /run) the mount point is created first.
# shellcheck disable=SC2086 # word splitting intended
set -- $VCAN_VM_SHARES
while [ $# -ge 3 ]; do
  mkdir -p "/newroot$3" 2>/dev/null
  [ -d "/newroot$3" ] || fatal "share $3 has no mount point in the guest"
  opts="$P9OPTS,cache=none"
  [ "$2" = ro ] && opts="$P9OPTS,cache=loose,ro"
  mount -t 9p -o "$opts" "$1" "/newroot$3" || fatal "cannot mount the $2 share $3 (9p tag $1)"
  echo "vcan-vm: $3 is shared from the host ($2)"
  shift 3
done

# busybox ip creates and raises the links (no exec over 9p); the host's iproute2, if any, shows the details.
ip link set dev lo up || fatal "cannot bring up lo"
for ifc in $VCAN_VM_IFACES; do
  ip link add dev "$ifc" type vcan || fatal "cannot create $ifc (ip link add dev $ifc type vcan)"
  ip link set dev "$ifc" up || fatal "cannot bring up $ifc"
done
HOSTIP=""
for p in /usr/sbin/ip /sbin/ip /usr/bin/ip /bin/ip; do
  [ -x "/newroot$p" ] && HOSTIP="$p" && break
done
for ifc in $VCAN_VM_IFACES; do
  if [ -n "$HOSTIP" ]; then
    echo "vcan-vm: ip -details link show $ifc"
    chroot /newroot "$HOSTIP" -details link show dev "$ifc" || fatal "$ifc does not exist after creating it"
  else
    echo "vcan-vm: ip link show $ifc"
    ip link show dev "$ifc" || fatal "$ifc does not exist after creating it"
  fi
done
echo "vcan-vm: ready after $(cut -d' ' -f1 /proc/uptime) s of guest uptime (modules loaded at $MODULES_AT s); running in $VCAN_VM_CWD: $VCAN_VM_CMDLINE"

env -i /bin/chroot /newroot /bin/sh /run/vcan-vm/run.sh </dev/null
status=$?
echo "$status" >/results/status || fatal "cannot write the exit status to the results share"
sync
echo "vcan-vm: command exited with status $status after $(cut -d' ' -f1 /proc/uptime) s of guest uptime"
poweroff -f
sleep 10
