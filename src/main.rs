fn main(){ let _ = eframe::run_native; }
