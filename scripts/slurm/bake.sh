#!/usr/bin/env bash
# Bakes a world on a Slurm cluster: one array job of N shards per series pass, each pass's
# merge a job that depends on its array (afterok), the next pass's array on that merge.
#
#   scripts/slurm/bake.sh TEXELS SCENE OUT.exr SHARDS [BAKE OPTIONS...]
#
# e.g. scripts/slurm/bake.sh city.texels city.toml city.exr 16 --spp 256 --bounces 3
#
# Every node must see TEXELS, SCENE and OUT's directory at the same paths (a shared file
# system), and `guidebake` on its PATH (or set GUIDEBAKE=/path/to/guidebake). The chain of
# a series bake of B bounces is
#     pass 0: array 0..N-1 of `bake --pass 0 --shard I/N --resume`  -> `merge --pass 0`
#     pass 1: array of `bake --pass 1 ...` (afterok: merge 0)       -> `merge --pass 1`
#     ...                                                            -> `merge --pass B`: OUT.exr
# (pass 0 is the direct light alone, docs/bake.md).
# A shard whose bake dies (killed, out of memory, node lost) is run again with --resume by
# its job script (GUIDEBAKE_ATTEMPTS times, default 3) and requeued by Slurm on node
# failure (--requeue); tiles already committed are not baked again, and the lightmap is the
# same bytes as one `guidebake bake` with the same options. `--transport path` has the one
# pass 1; series passes 0..B, B = --bounces (default 3).
#
# Environment: GUIDEBAKE (the binary), GUIDEBAKE_CPUS (cores per shard, default 1; the
# shard's --threads), GUIDEBAKE_ATTEMPTS, GUIDEBAKE_SLURM_WAIT=1 (block until the final
# merge has finished; exit with its status), and Slurm's own SBATCH_PARTITION,
# SBATCH_ACCOUNT, SBATCH_TIMELIMIT... for every job. Prints the job ids.
set -euo pipefail

if (($# < 4)); then
    sed -n '2,24p' "$0" >&2
    exit 2
fi
texels=$(realpath -m "$1")
scene=$(realpath -m "$2")
out=$(realpath -m "$3")
shards=$4
shift 4
bake_args=("$@")
here=$(cd "$(dirname "$0")" && pwd)
bin=${GUIDEBAKE:-$(command -v guidebake || true)}
if [[ -z $bin ]]; then
    echo "bake.sh: guidebake is not on PATH; set GUIDEBAKE=/path/to/guidebake" >&2
    exit 2
fi
bin=$(realpath "$bin")
cpus=${GUIDEBAKE_CPUS:-1}
attempts=${GUIDEBAKE_ATTEMPTS:-3}
[[ $shards =~ ^[1-9][0-9]*$ ]] || { echo "bake.sh: SHARDS must be a positive number, not '$shards'" >&2; exit 2; }

# Passes: the options' last --transport and --bounces win, as in the command line.
passes=3
transport=series
for ((i = 0; i < ${#bake_args[@]}; i++)); do
    case ${bake_args[i]} in
        --bounces) passes=${bake_args[i + 1]} ;;
        --bounces=*) passes=${bake_args[i]#*=} ;;
        --transport) transport=${bake_args[i + 1]} ;;
        --transport=*) transport=${bake_args[i]#*=} ;;
    esac
done
first=0
[[ $transport == series ]] || { first=1; passes=1; }

logs="$(dirname "$out")/$(basename "$out").slurm"
mkdir -p "$logs"
name=$(basename "$out" .exr)
previous=()
for ((pass = first; pass <= passes; pass++)); do
    array=$(sbatch --parsable --requeue "${previous[@]}" \
        --job-name="$name-bake-$pass" --array="0-$((shards - 1))" --cpus-per-task="$cpus" \
        --output="$logs/bake-$pass-%a.log" \
        "$here/shard.sbatch" "$bin" "$attempts" "$texels" "$scene" "$out" "$pass" "$shards" \
        "${bake_args[@]}")
    array=${array%%;*}
    wait=()
    if ((pass == passes)) && [[ ${GUIDEBAKE_SLURM_WAIT:-0} == 1 ]]; then
        wait=(--wait)
    fi
    echo "pass $pass: shards in job $array"
    merge_log="$logs/merge-$pass.log"
    merge=$(sbatch --parsable "${wait[@]}" --dependency="afterok:$array" --kill-on-invalid-dep=yes \
        --job-name="$name-merge-$pass" --output="$merge_log" \
        "$here/merge.sbatch" "$bin" "$texels" "$out" "$pass" "$shards") || {
        echo "pass $pass: the merge failed (see $merge_log and $logs/)" >&2
        exit 1
    }
    merge=${merge%%;*}
    echo "pass $pass: merge in job $merge"
    previous=(--dependency="afterok:$merge" --kill-on-invalid-dep=yes)
done
