from lirm.engine.bench.export_bench import ExportBenchConfig, run_export_bench


def test_export_bench_times_every_stage():
    figures = run_export_bench(ExportBenchConfig(grid=48, faces=2000, texture=128))
    assert set(figures["seconds"]) == {"sdf_grid", "marching_cubes", "decimate", "unwrap", "bake", "write"}
    assert 0 < figures["faces"] <= 2000 and figures["glb_bytes"] > 1000
    assert figures["total_seconds"] > 0


def test_real_asset_round_trip_looks_like_the_original(shared_data, tmp_path):
    """DamagedHelmet as a field, exported and rendered against the original under an HDRI (small
    settings: 28.4 dB measured; `lirm bench export --model ... --grid 192` gave 30.7 dB at 1024^2)."""
    from pathlib import Path

    from lirm.engine.bench.export_bench import RoundTripConfig, run_asset_round_trip

    figures = run_asset_round_trip(RoundTripConfig(
        shared_data / "pbr_models" / "DamagedHelmet_gltf" / "DamagedHelmet.gltf", shared_data / "envmaps" / "venice_sunset_1k.hdr",
        views=2, size=128, grid=96, faces=5000, texture=256, samples=200_000, sheet=tmp_path / "sheet.png"))
    assert figures["beauty_psnr"] >= 25.0, figures
    assert Path(figures["sheet"]).is_file()
