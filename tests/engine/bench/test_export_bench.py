from lirm.engine.bench.export_bench import ExportBenchConfig, run_export_bench


def test_export_bench_times_every_stage():
    figures = run_export_bench(ExportBenchConfig(grid=48, faces=2000, texture=128))
    assert set(figures["seconds"]) == {"sdf_grid", "marching_cubes", "decimate", "unwrap", "bake", "write"}
    assert 0 < figures["faces"] <= 2000 and figures["glb_bytes"] > 1000
    assert figures["total_seconds"] > 0
