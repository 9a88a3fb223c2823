use chromacal::calibrate::journal::{Journal, JournalHeader, JOURNAL_FORMAT, JOURNAL_VERSION};
use chromacal::calibrate::plan::{make_plan, PlanConfig};
use chromacal::calibrate::run::run_plan;
use chromacal::fit::{fit_monitor, FitOptions};
use chromacal::instrument::Instrument;
use chromacal::instrument::simulated::SimulatedInstrumentSpec;
use chromacal::measurement::Units;
use chromacal::sim::presets::preset;
use chromacal::sim::rig::SimulatedRig;

#[tokio::test]
async fn scratch() {
    for name in ["crt", "lcd"] {
        let mut rig = SimulatedRig::new(preset(name).unwrap(), SimulatedInstrumentSpec::default(), 0.2, None).unwrap();
        let plan = make_plan(&PlanConfig::default()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let header = JournalHeader { format: JOURNAL_FORMAT.into(), version: JOURNAL_VERSION, run_id: "x".into(), started: "now".into(), config_digest: "".into(), config: "".into(), display: "sim".into(), instrument: rig.instrument.info(), units: Units::Absolute, plan };
        let mut journal = Journal::create(&dir.path().join("j.jsonl"), header).unwrap();
        let t = std::time::Instant::now();
        run_plan(&mut journal, &mut rig.display, &mut rig.instrument, rig.clock.as_ref(), 3, &mut |_| {}).await.unwrap();
        let run_time = t.elapsed();
        let t = std::time::Instant::now();
        let fit = fit_monitor(&journal.measurement_set(), &FitOptions::default()).unwrap();
        eprintln!("{name}: run {:?} fit {:?} virtual {:.0}s", run_time, t.elapsed(), rig.clock.now());
        let mut r = fit.report.clone();
        r.held_out_patches.clear();
        eprintln!("{}", toml::to_string(&r).unwrap());
        eprintln!("truth: {:?}", rig.monitor.lock().unwrap().true_model());
        eprintln!("model: {:?}", fit.model);
    }
}
