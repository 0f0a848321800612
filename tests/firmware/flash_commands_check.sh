#!/usr/bin/env bash
# flash_commands_check.sh FIRMWARE_BUILD_DIR — the flashing commands that the firmware
# project's `flash-commands` target prints (docs/hardware.md, "Flashing") name images that
# exist and fit the part, and configurations that Debian's openocd parses. No probe is needed:
# openocd reads its interface and target scripts, then the check stops it before it looks for
# an adapter (`-c shutdown` in place of `program`).
set -euo pipefail
dir="$1"
out=$(cmake --build "$dir" --target flash-commands 2>&1) || { echo "$out"; exit 1; }
mapfile -t openocd_lines < <(grep '^openocd ' <<<"$out")
mapfile -t stflash_lines < <(grep '^st-flash ' <<<"$out")
# One board per "# ..." heading: the sink and one sensor node per id built.
boards=$(grep -c '^# ' <<<"$out")
if ((boards < 2 || ${#openocd_lines[@]} != boards || ${#stflash_lines[@]} != boards)); then
    echo "expected one openocd and one st-flash line per board (sink + nodes), got:"; echo "$out"; exit 1
fi
status=0
for line in "${openocd_lines[@]}"; do
    elf=$(sed -n "s/.*-c 'program \([^ ]*\) verify reset exit'.*/\1/p" <<<"$line")
    [[ -f "$elf" ]] || { echo "no image at $elf (from: $line)"; status=1; continue; }
    # The same -f arguments, in order: shutdown as soon as the scripts are read.
    read -r -a args <<<"$(sed "s/ -c '.*//" <<<"$line")"
    if ! log=$("${args[@]}" -c shutdown 2>&1); then
        echo "openocd does not accept the configuration of: $line"; echo "$log"; status=1
    else
        echo "ok: ${args[*]} (image $(basename "$elf"))"
    fi
done
for line in "${stflash_lines[@]}"; do
    read -r _ _ _ bin address <<<"$line"
    [[ -f "$bin" ]] || { echo "no image at $bin (from: $line)"; status=1; continue; }
    [[ "$address" == 0x08000000 ]] || { echo "flash base of an STM32 is 0x08000000, not $address"; status=1; }
    case "$bin" in
        *f103*) limit=$((64 * 1024)) ;;   # STM32F103C8: 64 KiB of flash
        *f407*) limit=$((1024 * 1024)) ;; # STM32F407VG: 1 MiB
        *) echo "unknown part of $bin"; status=1; continue ;;
    esac
    size=$(stat -c %s "$bin")
    ((size <= limit)) || { echo "$bin is $size bytes, the part has $limit"; status=1; }
    command -v st-flash >/dev/null || { echo "st-flash (stlink-tools) is not installed"; status=1; }
    echo "ok: $(basename "$bin") $size of $limit bytes at $address"
done
exit $status
