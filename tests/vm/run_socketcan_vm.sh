#!/usr/bin/env bash
# Boots Debian's own kernel in qemu (TCG; no KVM here) with a busybox initramfs holding the
# CAN modules and the test program, creates vcan0 inside the VM and runs the test there.
# The kernel package is fetched from Debian's archive with `apt-get download` (cached in
# WORKDIR) and unpacked with dpkg-deb, never installed.
# Usage: run_socketcan_vm.sh TEST_BINARY WORKDIR
set -euo pipefail
test_bin="$(readlink -f "$1")"
work="$2"
mkdir -p "$work"
cd "$work"

kpkg="$(apt-cache depends linux-image-amd64 2>/dev/null | sed -n 's/.*Depends: \(linux-image-[0-9].*\)/\1/p' | head -1)"
if [[ -z "$kpkg" ]]; then
  apt-get update -qq
  kpkg="$(apt-cache depends linux-image-amd64 | sed -n 's/.*Depends: \(linux-image-[0-9].*\)/\1/p' | head -1)"
fi
if [[ ! -d "kernel-$kpkg" ]]; then
  rm -f "$kpkg"_*.deb
  apt-get download "$kpkg" >/dev/null 2>&1
  dpkg-deb -x "$kpkg"_*.deb "kernel-$kpkg.tmp"
  mv "kernel-$kpkg.tmp" "kernel-$kpkg"
fi
kroot="$work/kernel-$kpkg"
kver="$(ls "$kroot/lib/modules" | head -1)"
vmlinuz="$kroot/boot/vmlinuz-$kver"

# --- initramfs --------------------------------------------------------------------------
root="$work/initramfs"
rm -rf "$root"
mkdir -p "$root"/{bin,sbin,proc,sys,dev,tmp,lib/modules/"$kver"}
cp /bin/busybox "$root/bin/busybox"
for a in sh mount modprobe ip poweroff echo cat sleep; do ln -s busybox "$root/bin/$a"; done
for m in net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko; do
  mkdir -p "$root/lib/modules/$kver/kernel/$(dirname "$m")"
  cp "$kroot/lib/modules/$kver/kernel/$m" "$root/lib/modules/$kver/kernel/$m"
done
"$root/bin/busybox" depmod -b "$root" "$kver"
# The test program and the shared libraries it needs, at their own paths.
cp "$test_bin" "$root/bin/socketcan_vm_test"
for lib in $(ldd "$test_bin" | grep -o '/[^ ]*'); do
  mkdir -p "$root$(dirname "$lib")"
  cp -L "$lib" "$root$lib"
done
cat > "$root/init" <<'INIT'
#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
modprobe vcan && modprobe can-raw || echo "modprobe failed"
ip link add dev vcan0 type vcan
ip link set vcan0 mtu 72
ip link set vcan0 up
/bin/socketcan_vm_test vcan0
poweroff -f
INIT
chmod +x "$root/init"
(cd "$root" && find . | cpio -o -H newc --quiet | gzip -1) > "$work/initramfs.gz"

# --- boot ---------------------------------------------------------------------------------
log="$work/console.log"
timeout 300 qemu-system-x86_64 -accel tcg -m 512 -smp 1 -nographic -no-reboot \
  -kernel "$vmlinuz" -initrd "$work/initramfs.gz" \
  -append "console=ttyS0 quiet loglevel=3 panic=-1" > "$log" 2>&1 || true
sed -n '/^ok  \|^FAIL\|kernel_drops\|SOCKETCAN-VM-RESULT\|modprobe failed/p' "$log"
grep -q 'SOCKETCAN-VM-RESULT PASS' "$log" || { echo "--- console ---"; tail -40 "$log"; exit 1; }
